"""Top-down pictures of an episode (opencv; no GUI): lot, spots, vehicles, the ego's rays, trajectories."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from avp_world.geometry import rect_corners
from avp_world.lot import LotMap

# BGR colours
ROAD, BG, VACANT, OCCUPIED = (193, 193, 193), (40, 40, 40), (80, 200, 80), (90, 90, 200)
PARKED, DYNAMIC, EGO, RAY, EGO_PATH, DYN_PATH = (200, 120, 60), (0, 220, 255), (40, 40, 230), (0, 165, 255), (
    60, 60, 255), (0, 200, 255)


class Canvas:
    def __init__(self, lot: LotMap, px_per_m: float = 20.0, margin: float = 1.5):
        xmin, ymin, xmax, ymax = lot.bounds()
        self.lot, self.s, self.x0, self.y1, self.m = lot, px_per_m, xmin - margin, ymax + margin, margin
        w = int((xmax - xmin + 2 * margin) * px_per_m)
        h = int((ymax - ymin + 2 * margin) * px_per_m)
        self.img = np.full((h, w, 3), BG, dtype=np.uint8)

    def px(self, pts: np.ndarray) -> np.ndarray:
        pts = np.asarray(pts, dtype=float)
        return np.stack([(pts[..., 0] - self.x0) * self.s, (self.y1 - pts[..., 1]) * self.s], -1).round().astype(
            np.int32)

    def poly(self, corners: np.ndarray, color, filled: bool = True, thickness: int = 2) -> None:
        p = self.px(corners)
        if filled:
            cv2.fillPoly(self.img, [p], color, lineType=cv2.LINE_AA)
        else:
            cv2.polylines(self.img, [p], True, color, thickness, lineType=cv2.LINE_AA)

    def line(self, pts: np.ndarray, color, thickness: int = 2) -> None:
        if len(pts) >= 2:
            cv2.polylines(self.img, [self.px(pts)], False, color, thickness, lineType=cv2.LINE_AA)

    def text(self, xy, s: str, color=(255, 255, 255), scale: float = 0.45) -> None:
        p = self.px(np.array(xy))
        cv2.putText(self.img, s, (int(p[0]), int(p[1])), cv2.FONT_HERSHEY_SIMPLEX, scale, color, 1, cv2.LINE_AA)

    def save(self, path: str | Path) -> None:
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        cv2.imwrite(str(path), self.img)


def draw_lot(c: Canvas, occupied_ids: set[int]) -> None:
    lot = c.lot
    c.poly(lot.boundary, ROAD)
    for k, s in enumerate(lot.spots):
        c.poly(lot.spot_corners[k], OCCUPIED if s.id in occupied_ids else VACANT, filled=False, thickness=2)
        c.text((s.x - 0.6, s.y - 0.3), str(s.id), (60, 60, 60), 0.35)
    c.poly(lot.boundary, (255, 255, 255), filled=False, thickness=2)


def render_episode(lot: LotMap, ego_traj: np.ndarray, ego_dims: tuple[float, float], vehicles: dict,
                   occupied_ids: set[int], rays: np.ndarray | None, title: str, path: str | Path) -> None:
    """Final frame with trajectories.

    vehicles: id -> dict(traj (T,3), dims (l, w), dynamic bool, target int).
    rays: (n_ray, 2) endpoints of the last observation's rays (drawn from the ego's final pose).
    """
    c = Canvas(lot)
    draw_lot(c, occupied_ids)
    if rays is not None and len(rays):
        # the region the rays sweep (what the ego sees), translucent, with every 8th ray drawn
        overlay = c.img.copy()
        cv2.fillPoly(overlay, [c.px(rays)], RAY, lineType=cv2.LINE_AA)
        c.img = cv2.addWeighted(overlay, 0.3, c.img, 0.7, 0)
        o = c.px(np.asarray(ego_traj)[-1][:2])
        for e in c.px(rays)[::8]:
            cv2.line(c.img, tuple(int(v) for v in o), tuple(int(v) for v in e), RAY, 1, cv2.LINE_AA)
    for vid, v in vehicles.items():
        traj = np.asarray(v["traj"])
        if v["dynamic"]:
            c.line(traj[:, :2], DYN_PATH, 2)
            if v.get("target", -1) >= 0:
                k = lot.spot_index(v["target"])
                c.poly(lot.spot_corners[k], DYN_PATH, filled=False, thickness=1)
        c.poly(rect_corners(traj[-1], *v["dims"]), DYNAMIC if v["dynamic"] else PARKED)
        if v["dynamic"]:
            c.text(traj[-1][:2], str(vid), (0, 0, 0), 0.4)
    c.line(np.asarray(ego_traj)[:, :2], EGO_PATH, 2)
    c.poly(rect_corners(np.asarray(ego_traj)[-1], *ego_dims), EGO)
    cv2.putText(c.img, title, (8, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1, cv2.LINE_AA)
    legend = [("ego", EGO), ("ego path", EGO_PATH), ("dynamic vehicle + path/target", DYNAMIC), ("parked", PARKED),
              ("vacant spot", VACANT), ("occupied spot", OCCUPIED), ("sensed region / rays", RAY)]
    x = 8
    h = c.img.shape[0] - 8
    for name, col in legend:
        cv2.rectangle(c.img, (x, h - 10), (x + 10, h), col, -1)
        cv2.putText(c.img, name, (x + 14, h), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (255, 255, 255), 1, cv2.LINE_AA)
        x += 22 + 7 * len(name)
    c.save(path)
