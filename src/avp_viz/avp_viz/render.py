"""Top-down pictures of an episode (opencv; no GUI): lot, spots, vehicles, the ego's rays, trajectories."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from avp_viz.palette import EGO_RGB
from avp_world.geometry import rect_corners
from avp_world.lot import LotMap

# BGR colours
ROAD, BG, VACANT, OCCUPIED = (193, 193, 193), (40, 40, 40), (80, 200, 80), (90, 90, 200)
PARKED, DYNAMIC, EGO, RAY, EGO_PATH, DYN_PATH = (200, 120, 60), (0, 220, 255), (40, 40, 230), (0, 165, 255), (
    60, 60, 255), (0, 200, 255)
#: ego i's colour (BGR) among several egos: the live scene's (avp_viz.palette)
EGO_BGR = [(int(255 * b), int(255 * g), int(255 * r)) for r, g, b in EGO_RGB]


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


def legend_band(width: int, entries, scale: float = 0.32, box: int = 8, row: int = 18, bg: int = 30) -> np.ndarray:
    """A band of ``width`` px holding a coloured box and a name for each (name, BGR colour) of ``entries``, wrapped
    onto as many rows as the width needs (a name is never cut at the picture's edge)."""
    font = cv2.FONT_HERSHEY_SIMPLEX
    items = [(name, col, box + 3 + cv2.getTextSize(name, font, scale, 1)[0][0]) for name, col in entries]
    rows: list[list] = [[]]
    x = 6
    for item in items:
        if rows[-1] and x + item[2] > width - 6:
            rows.append([])
            x = 6
        rows[-1].append((x, *item))
        x += item[2] + 10
    band = np.full((row * len(rows), width, 3), bg, dtype=np.uint8)
    for r, items_of_row in enumerate(rows):
        y = r * row + row // 2 + box // 2
        for x, name, col, _w in items_of_row:
            cv2.rectangle(band, (x, y - box), (x + box, y), tuple(int(v) for v in col), -1)
            cv2.putText(band, name, (x + box + 3, y), font, scale, (255, 255, 255), 1, cv2.LINE_AA)
    return band


def render_episode(lot: LotMap, ego_traj: np.ndarray, ego_dims: tuple[float, float], vehicles: dict,
                   occupied_ids: set[int], rays: np.ndarray | None, title: str, path: str | Path,
                   other_egos: dict | None = None) -> None:
    """Final frame with trajectories.

    vehicles: id -> dict(traj (T,3), dims (l, w), dynamic bool, target int).
    rays: (n_ray, 2) endpoints of the last observation's rays (drawn from the ego's final pose).
    other_egos: several egos: ego i (>= 1) -> (traj (T,3), dims (l, w)), each drawn with its path in its colour
    (:data:`EGO_BGR`; ego 0 then in ``EGO_BGR[0]``).
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
    others = {i: e for i, e in (other_egos or {}).items() if len(e[0])}
    ego_col, path_col = (EGO_BGR[0], EGO_BGR[0]) if others else (EGO, EGO_PATH)
    for i, (traj, dims) in sorted(others.items()):
        col = EGO_BGR[i % len(EGO_BGR)]
        c.line(np.asarray(traj)[:, :2], col, 2)
        c.poly(rect_corners(np.asarray(traj)[-1], *dims), col)
        c.text(np.asarray(traj)[-1][:2], str(i), (0, 0, 0), 0.4)
    c.line(np.asarray(ego_traj)[:, :2], path_col, 2)
    c.poly(rect_corners(np.asarray(ego_traj)[-1], *ego_dims), ego_col)
    cv2.putText(c.img, title, (8, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1, cv2.LINE_AA)
    egos = [(f"ego {i} + path", EGO_BGR[i % len(EGO_BGR)]) for i in [0, *sorted(others)]] if others else \
        [("ego", EGO), ("ego path", EGO_PATH)]
    legend = [*egos, ("dynamic vehicle + path/target", DYNAMIC), ("parked", PARKED), ("vacant spot", VACANT),
              ("occupied spot", OCCUPIED), ("sensed region / rays", RAY)]
    c.img = np.vstack([c.img, legend_band(c.img.shape[1], legend, scale=0.4, box=10, row=20)])
    c.save(path)
