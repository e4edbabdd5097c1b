"""An animated picture of a whole episode from a recorded bag (``avp demo`` writes ``out/demo/episode.gif``).

Everything drawn comes from the topics of the live graph as recorded in the bag (``avp_bag.recorder``), never from
an in-process recomputation:

* the lot (``lot_map``) with every spot filled by its belief b_t (``beliefs``; eqs. 7-8, §V-B): green = 0 (free),
  red = 1 (taken), grey = never observed;
* the sensed region (``observation`` rays, §III-A), the observed vehicles (filled; dynamic ones with their
  history trail) and the agents the ego does not see (``debug/ground_truth``, thin outlines — debug only);
* the intentions of every observed dynamic vehicle (``intentions``, §V-A): a line to each spot with
  eta >= ``MIN_ETA`` and the probability at the spot, a ring with its probability at each exploration point;
* the predicted trajectories with their probabilities (``predictions``, §V-C);
* the ego's own intention when the method has one (``ego_intention``, Table I "Implicit"): its three most
  wanted spots numbered;
* the ego and its plan (``decision``: green = parking, blue = exploring; the goal spot outlined).

Several egos (``avp demo --egos K``): the view is ego 0's (its topics under ``/avp/ego0/``); every other ego is drawn
from the ground truth in its own colour (:data:`EGO_BGR`, those of the live scene) with its plan and chosen spot
(``/avp/ego<i>/decision``).

Frames are every ``stride``-th step, drawn at ``px_per_m`` and written as an animated GIF with Pillow (a pinned
dependency; palette per frame, frame differences only), kept small by the stride and the scale.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from avp_viz.palette import mark_seen
from avp_viz.render import DYNAMIC, EGO, EGO_BGR, PARKED, RAY, ROAD, Canvas, legend_band
from avp_world.geometry import rect_corners
from avp_world.lot import LotMap

MIN_ETA = 0.1  # intentions drawn from this probability on
FREE, TAKEN, UNSEEN = np.array([70, 170, 70]), np.array([60, 60, 210]), (85, 85, 85)  # BGR
PEDESTRIAN = (30, 105, 255)  # BGR orange-red
PARK, EXPLORE, EGO_RANK, GHOST, WHITE = (60, 220, 60), (255, 150, 40), (230, 60, 230), (235, 235, 235), (255, 255,
                                                                                                          255)
PRED_COLOURS = [(0, 220, 255), (255, 200, 0), (0, 140, 255), (200, 120, 255), (120, 255, 120)]
MODE_NAMES = {0: "idle", 1: "park", 2: "explore"}


@dataclass
class EpisodeRecording:
    """One episode's recorded messages, keyed by step (the last episode of the bag)."""

    lot: LotMap
    observations: dict = field(default_factory=dict)  # step -> avp_world Observation
    ground_truth: dict = field(default_factory=dict)  # step -> GroundTruth message
    beliefs: dict = field(default_factory=dict)  # step -> (N_S,) b_t in lot spot order
    intentions: dict = field(default_factory=dict)  # step -> [Intention]
    ego_intention: dict = field(default_factory=dict)  # step -> Intention
    predictions: dict = field(default_factory=dict)  # step -> [PredictedTrajectory]
    decisions: dict = field(default_factory=dict)  # step -> PlannerDecision message
    status: object = None  # the last EpisodeStatus
    other_decisions: dict = field(default_factory=dict)  # several egos: ego i (>= 1) -> step -> PlannerDecision

    @property
    def steps(self) -> list[int]:
        return sorted(self.ground_truth)


TOPICS = ("/avp/lot_map", "/avp/observation", "/avp/debug/ground_truth", "/avp/beliefs", "/avp/intentions",
          "/avp/ego_intention", "/avp/predictions", "/avp/decision", "/avp/episode_status")
_VIEW = {"/avp/observation", "/avp/beliefs", "/avp/intentions", "/avp/ego_intention", "/avp/predictions",
         "/avp/decision"}  # ego 0's own topics


def read_recording(bag: Path, egos: int = 1) -> EpisodeRecording:
    """The last episode of ``bag`` (ValueError if it lacks the lot map or ground truth); ``egos`` > 1: a graph of
    several egos, seen from ego 0 (the module docstring)."""
    from avp_bag.reader import BagReader
    from avp_common.conversions import lot_from_msg, observation_from_msg, predictions_from_msg
    from avp_perception.conversions import intentions_from_msg

    rec: EpisodeRecording | None = None
    lot = None
    reader = BagReader(Path(bag))
    rename = {f"/avp/ego0/{t[5:]}": t for t in _VIEW} if egos > 1 else {}
    others = {f"/avp/ego{i}/decision": i for i in range(1, egos)}
    for topic, msgtype, _t, raw in reader.messages([*TOPICS, *rename, *others]):
        msg = reader.deserialize(raw, msgtype)
        if topic in others:
            if rec is not None:
                rec.other_decisions.setdefault(others[topic], {}).setdefault(int(msg.step), msg)
            continue
        topic = rename.get(topic, topic)
        if topic == "/avp/lot_map":
            lot = lot_from_msg(msg, source=f"{bag}:/avp/lot_map")
            rec = rec or EpisodeRecording(lot)
            continue
        if rec is None:
            continue
        if topic == "/avp/episode_status":
            rec.status = msg
            continue
        k = int(msg.step)
        if topic == "/avp/debug/ground_truth":
            if k == 0 and max(rec.ground_truth, default=0) > 0:
                rec = EpisodeRecording(lot)  # a new episode (reset): keep the last one (a re-sent step 0 is not)
            rec.ground_truth[k] = msg
        elif topic == "/avp/observation":
            rec.observations.setdefault(k, observation_from_msg(msg))
        elif topic == "/avp/beliefs":
            b = dict(zip(np.asarray(msg.spot_ids).tolist(), np.asarray(msg.beliefs, dtype=float).tolist(),
                         strict=True))
            rec.beliefs[k] = np.array([b.get(int(i), math.nan) for i in lot.spot_ids])
        elif topic == "/avp/intentions":
            rec.intentions[k] = intentions_from_msg(msg, lot)
        elif topic == "/avp/ego_intention":
            its = intentions_from_msg(msg, lot)
            if its:
                rec.ego_intention[k] = its[0]
        elif topic == "/avp/predictions":
            rec.predictions[k] = predictions_from_msg(msg)
        elif topic == "/avp/decision":
            rec.decisions.setdefault(k, msg)
    if rec is None or not rec.ground_truth:
        raise ValueError(f"{bag}: needs /avp/lot_map and /avp/debug/ground_truth")
    return rec


def _belief_colour(b: float) -> tuple[int, int, int]:
    if not math.isfinite(b):
        return UNSEEN
    c = (1.0 - b) * FREE + b * TAKEN
    return tuple(int(v) for v in c)


def render_frame(rec: EpisodeRecording, k: int, seen: np.ndarray, px_per_m: float = 12.0,
                 title: str = "") -> np.ndarray:
    """The picture of step ``k`` (BGR); ``seen``: spots observed up to step k (lot order)."""
    c = Canvas(rec.lot, px_per_m, margin=1.0)
    obs = rec.observations.get(k)
    _draw_beliefs_and_rays(c, rec, k, seen, obs)
    colour_of = _draw_vehicles(c, rec, k, obs)
    _draw_intentions(c, rec, k, obs, colour_of)
    _draw_predictions(c, rec, k, colour_of)
    d = rec.decisions.get(k)
    _draw_plan_and_ego(c, rec.lot, d, obs, EGO_BGR[0] if rec.other_decisions else EGO)
    _draw_other_egos(c, rec, k, with_first=obs is None)
    return np.vstack([_header(c, k, obs, d, title), c.img, _legend(c, rec)])


def _draw_beliefs_and_rays(c: Canvas, rec: EpisodeRecording, k: int, seen: np.ndarray, obs) -> None:
    """The lot, its spots coloured by belief (grey until seen) and the area the rays cover."""
    lot = rec.lot
    c.poly(lot.boundary, ROAD)
    b = rec.beliefs.get(k)
    for i in range(lot.n_spots):
        val = float(b[i]) if b is not None and seen[i] else math.nan
        c.poly(lot.spot_corners[i], _belief_colour(val))
        c.poly(lot.spot_corners[i], (40, 40, 40), filled=False, thickness=1)
    if obs is not None and len(obs.ray_ranges):
        overlay = c.img.copy()
        cv2.fillPoly(overlay, [c.px(obs.ray_endpoints())], RAY, lineType=cv2.LINE_AA)
        c.img = cv2.addWeighted(overlay, 0.25, c.img, 0.75, 0)


def _draw_vehicles(c: Canvas, rec: EpisodeRecording, k: int, obs) -> dict[int, tuple]:
    """Unseen agents as thin outlines (ground truth, debug only), the observed vehicles with their trails;
    returns the colour given to each observed moving vehicle."""
    seen_ids = {int(v.id) for v in obs.vehicles} if obs is not None else set()
    gt = rec.ground_truth.get(k)
    if gt is not None:
        for a in gt.agents:
            if a.kind == 1 and int(a.id) not in seen_ids:
                c.poly(rect_corners(np.array([a.pose.x, a.pose.y, a.pose.theta]), a.length, a.width), GHOST,
                       filled=False, thickness=1)
        seen_peds = {int(q.id) for q in obs.pedestrians} if obs is not None else set()
        for a in gt.agents:  # pedestrians (eq. 2): a ring where unseen, a filled disc where the ego sees them
            if a.kind == 2 and int(a.id) not in seen_peds:
                cv2.circle(c.img, tuple(int(x) for x in c.px(np.array([a.pose.x, a.pose.y]))),
                           max(2, int(a.radius * c.s)), GHOST, 1, cv2.LINE_AA)
    for q in (obs.pedestrians if obs is not None else ()):
        cv2.circle(c.img, tuple(int(x) for x in c.px(np.asarray(q.position)[:2])), max(3, int(q.radius * c.s) + 1),
                   PEDESTRIAN, -1, cv2.LINE_AA)
    colour_of: dict[int, tuple] = {}
    if obs is not None:
        for v in obs.vehicles:
            if not v.is_static:
                colour_of[int(v.id)] = PRED_COLOURS[len(colour_of) % len(PRED_COLOURS)]
                c.line(np.asarray(v.history)[:, :2], colour_of[int(v.id)], 1)
            c.poly(rect_corners(np.asarray(v.pose), v.length, v.width), DYNAMIC if not v.is_static else PARKED)
    return colour_of


def _draw_intentions(c: Canvas, rec: EpisodeRecording, k: int, obs, colour_of: dict[int, tuple]) -> None:
    """A line from each vehicle to every spot it may want (eta at the spot), rings at exploration points, and
    the ego's own three most wanted spots numbered (implicit method)."""
    lot = rec.lot
    for it in rec.intentions.get(k, []):
        v = next((v for v in (obs.vehicles if obs is not None else ()) if int(v.id) == it.vehicle_id), None)
        if v is None:
            continue
        col = colour_of.get(it.vehicle_id, DYNAMIC)
        for sid, eta in zip(np.asarray(it.spot_ids).tolist(), np.asarray(it.spot_probabilities).tolist(),
                            strict=True):
            if eta < MIN_ETA:
                continue
            sx, sy = lot.spot_poses[lot.spot_index(int(sid)), :2]
            cv2.line(c.img, tuple(int(x) for x in c.px(np.asarray(v.pose[:2]))), tuple(int(x) for x in c.px((sx, sy))),
                     col, 1 + int(3 * eta), cv2.LINE_AA)
            c.text((sx - 0.9, sy + 0.2), f"{eta:.2f}", WHITE, 0.33)
        for q, eta in zip(np.asarray(it.exploration_points).reshape(-1, 3).tolist(),
                          np.asarray(it.exploration_probabilities).tolist(), strict=True):
            if eta >= MIN_ETA:  # an exploration point eta_hat: a ring with its probability
                cv2.circle(c.img, tuple(int(x) for x in c.px(np.asarray(q[:2]))), max(3, int(0.6 * c.s)), col,
                           1 + int(2 * eta), cv2.LINE_AA)
                c.text((q[0] + 0.7, q[1] - 0.3), f"{eta:.2f}", col, 0.33)


def _draw_predictions(c: Canvas, rec: EpisodeRecording, k: int, colour_of: dict[int, tuple]) -> None:
    """Predicted trajectories (width and label by probability), then the ego's own intention ranks."""
    for p in rec.predictions.get(k, []):
        if p.is_pedestrian or len(p.poses) < 2:
            continue
        col = colour_of.get(int(p.agent_id), DYNAMIC)
        c.line(np.asarray(p.poses)[:, :2], col, 1 + int(2 * p.probability))
        if p.probability < 0.999:
            c.text(np.asarray(p.poses)[-1, :2] + (0.2, 0.2), f"p={p.probability:.2f}", col, 0.33)
    ego_it = rec.ego_intention.get(k)
    if ego_it is not None:
        order = np.argsort(-np.asarray(ego_it.spot_probabilities), kind="stable")[:3]
        for rank, j in enumerate(order, start=1):
            sid = int(np.asarray(ego_it.spot_ids)[j])
            sx, sy = rec.lot.spot_poses[rec.lot.spot_index(sid), :2]
            c.text((sx - 0.4, sy - 1.2), f"#{rank}", EGO_RANK, 0.45)


def _draw_other_egos(c: Canvas, rec: EpisodeRecording, k: int, with_first: bool = False) -> None:
    """Several egos: egos 1..K-1 (ground truth) in their colours, each with its plan and chosen spot; ego 0 too
    (``with_first``) on steps without its observation (it has parked)."""
    gt = rec.ground_truth.get(k)
    if gt is None or not rec.other_decisions:
        return
    for a in gt.agents:
        i = int(a.id)
        if a.kind != 0 or (i == 0 and not with_first):
            continue
        col = EGO_BGR[i % len(EGO_BGR)]
        d = rec.other_decisions.get(i, {}).get(k)
        if d is not None:
            _draw_plan_and_ego(c, rec.lot, d, None, col, plan_colour=col)
        c.poly(rect_corners(np.array([a.pose.x, a.pose.y, a.pose.theta]), a.length, a.width), col)


def _draw_plan_and_ego(c: Canvas, lot, d, obs, ego_colour=EGO, plan_colour=None) -> None:
    """The planned path (parking or exploring), the chosen spot outlined, and the ego on top."""
    if d is not None:
        col = plan_colour or (PARK if d.mode == 1 else EXPLORE)
        pts = np.array([[q.pose.position.x, q.pose.position.y] for q in d.plan.poses]).reshape(-1, 2)
        c.line(pts, col, 2)
        if d.mode == 1 and d.spot_id >= 0 and lot.has_spot(int(d.spot_id)):
            c.poly(lot.spot_corners[lot.spot_index(int(d.spot_id))], col, filled=False, thickness=3)
    if obs is not None:
        c.poly(rect_corners(np.asarray(obs.ego_pose), obs.ego_length, obs.ego_width), ego_colour)


def _header(c: Canvas, k: int, obs, d, title: str) -> np.ndarray:
    band = np.full((22, c.img.shape[1], 3), 30, dtype=np.uint8)
    t = k * (obs.dt if obs is not None else 0.1)
    mode = f"{MODE_NAMES.get(int(d.mode), '?')}{' spot ' + str(d.spot_id) if d is not None and d.mode == 1 else ''}" \
        if d is not None else "-"
    cv2.putText(band, f"{title}  t={t:5.1f}s  {mode}", (6, 15), cv2.FONT_HERSHEY_SIMPLEX, 0.42, WHITE, 1,
                cv2.LINE_AA)
    return band


def _legend(c: Canvas, rec: EpisodeRecording) -> np.ndarray:
    """The colours' names, wrapped to the picture's width; with several egos each ego's colour by its index."""
    egos = [(f"ego {i}", EGO_BGR[i % len(EGO_BGR)]) for i in [0, *sorted(rec.other_decisions)]] \
        if rec.other_decisions else [("ego", EGO)]
    return legend_band(c.img.shape[1], [
        ("b=0", FREE), ("b=1", TAKEN), ("unseen", UNSEEN), *egos, ("plan", PARK), ("explore", EXPLORE),
        ("seen car", DYNAMIC), ("parked", PARKED), ("pedestrian", PEDESTRIAN), ("not seen", GHOST),
        ("ego #rank", EGO_RANK)])


def render_frames(rec: EpisodeRecording, stride: int = 1, px_per_m: float = 12.0, title: str = "") -> list[np.ndarray]:
    """Frames of every ``stride``-th recorded step and of the last one (BGR)."""
    steps = rec.steps
    if not steps:
        return []
    chosen = steps[::max(1, int(stride))]
    if chosen[-1] != steps[-1]:
        chosen.append(steps[-1])
    seen = np.zeros(rec.lot.n_spots, dtype=bool)
    frames = []
    want = set(chosen)
    for k in steps:
        o = rec.observations.get(k)
        if o is not None:
            mark_seen(seen, rec.lot, o)
        if k in want:
            frames.append(render_frame(rec, k, seen, px_per_m, title))
    return frames


def write_gif(frames: list[np.ndarray], path: Path, frame_ms: int) -> Path:
    """Animated GIF (Pillow; loops), one adaptive palette per frame."""
    from PIL import Image

    if not frames:
        raise ValueError("no frames to write")
    imgs = [Image.fromarray(cv2.cvtColor(f, cv2.COLOR_BGR2RGB)).quantize(colors=64, method=Image.Quantize.FASTOCTREE,
                                                                           dither=Image.Dither.NONE) for f in frames]
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    imgs[0].save(path, save_all=True, append_images=imgs[1:], duration=int(frame_ms), loop=0, optimize=True,
                 disposal=1)
    return path


def episode_gif(bag: Path, path: Path, *, max_frames: int = 150, speed: float = 2.0, px_per_m: float | None = None,
                title: str = "", egos: int = 1) -> dict:
    """Read ``bag``, draw at most about ``max_frames`` frames and write them to ``path`` playing at ``speed`` times
    sim time; ``px_per_m`` None: 12, or less so that the lot's larger side fits 960 px (the DLP lot: 6.9).
    Returns {"frames", "stride", "bytes", "steps"}."""
    rec = read_recording(bag, egos)
    if px_per_m is None:
        xmin, ymin, xmax, ymax = rec.lot.bounds()
        px_per_m = min(12.0, 960.0 / max(xmax - xmin, ymax - ymin, 1e-9))
    steps = rec.steps
    stride = max(1, math.ceil(len(steps) / max(1, max_frames)))
    frames = render_frames(rec, stride, px_per_m, title)
    dt = next(iter(rec.observations.values())).dt if rec.observations else 0.1
    write_gif(frames, path, frame_ms=max(20, round(1000 * stride * dt / speed)))
    return {"frames": len(frames), "stride": stride, "bytes": Path(path).stat().st_size, "steps": len(steps)}
