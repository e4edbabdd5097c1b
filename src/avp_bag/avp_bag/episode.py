"""An episode read back from a bag: its lot, ground truth and last status, and the §VI-B metrics
recomputed from them (``avp metrics BAG``) beside the ones the simulator published live."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from avp_bag.reader import BagReader
from avp_common.conversions import lot_from_msg


def read_episode(bag: Path) -> dict:
    """Lot, ground truth and the last status of the (last) episode in a bag (read by
    :class:`avp_bag.reader.BagReader`: a damaged bag gives one error naming the file)."""
    lot = None
    gts: dict[int, object] = {}
    status = None
    reader = BagReader(bag)
    for topic, msgtype, _t, raw in reader.messages(("/avp/lot_map", "/avp/debug/ground_truth",
                                                     "/avp/episode_status")):
        msg = reader.deserialize(raw, msgtype)
        if topic == "/avp/lot_map":
            lot = lot_from_msg(msg, source=f"{bag}:/avp/lot_map")
        elif topic == "/avp/debug/ground_truth":
            if int(msg.step) == 0:
                gts = {}  # a new episode started (reset): keep the last one
            gts[int(msg.step)] = msg
        else:
            status = msg
    if lot is None or not gts or status is None:
        raise ValueError(f"{bag}: needs /avp/lot_map, /avp/debug/ground_truth and /avp/episode_status")
    return {"lot": lot, "ground_truth": [gts[k] for k in sorted(gts)], "status": status}


#: a one-ego episode's driven car j is the vehicle DRIVEN_ID + 1 + j of the recomputation (slot 1 + j of
#: avp_sim.core.egos)
DRIVEN_ID = 900_000
_AWAY = 1.0e6  # where a driven car is before it enters (no collision, no spot, out of every sensor's reach)


def _with_driven(gts, ids, dims, dynamic, targets, veh, brk):
    """The vehicle arrays with each driven car (``KIND_DRIVEN``, docs/teleop.md) appended: far away until it
    enters, never braking for the ego (a person drives it)."""
    driven = sorted({int(a.id) for g in gts for a in g.agents if a.kind == 3})
    if not driven:
        return ids, dims, dynamic, targets, veh, brk
    first = {}
    extra = np.full((len(gts), len(driven), 3), _AWAY)
    for k, g in enumerate(gts):
        for a in g.agents:
            if a.kind == 3:
                j = driven.index(int(a.id))
                first.setdefault(j, a)
                extra[k, j] = (a.pose.x, a.pose.y, a.pose.theta)
    return (np.concatenate([ids, [DRIVEN_ID + 1 + j for j in driven]]).astype(np.int64),
            np.concatenate([dims, [[first[j].length, first[j].width] for j in range(len(driven))]]),
            np.concatenate([dynamic, np.ones(len(driven), dtype=bool)]),
            np.concatenate([targets, -np.ones(len(driven), dtype=np.int64)]),
            np.concatenate([veh, extra], axis=1),
            np.concatenate([brk, np.zeros((len(gts), len(driven)), dtype=bool)], axis=1))


def metrics_from_bag(bag: Path) -> tuple[dict, dict]:
    """(recomputed, live) metrics of the episode in ``bag``."""
    from avp_sim.core.metrics import metrics_from_log, nan_to_none

    ep = read_episode(bag)
    gts, status, lot = ep["ground_truth"], ep["status"], ep["lot"]
    ego = np.array([[a.pose.x, a.pose.y, a.pose.theta] for g in gts for a in g.agents if a.kind == 0])
    first = [a for a in gts[0].agents if a.kind == 1]
    ids = np.array([a.id for a in first], dtype=np.int64)
    dims = np.array([[a.length, a.width] for a in first]).reshape(-1, 2)
    dynamic = np.array([not a.is_static for a in first], dtype=bool)
    targets = np.array([a.target_spot_id for a in first], dtype=np.int64)
    veh = np.array([[[a.pose.x, a.pose.y, a.pose.theta] for a in g.agents if a.kind == 1] for g in gts]).reshape(
        len(gts), len(first), 3)
    brk = np.array([[a.braking for a in g.agents if a.kind == 1] for g in gts], dtype=bool).reshape(len(gts), -1)
    ids, dims, dynamic, targets, veh, brk = _with_driven(gts, ids, dims, dynamic, targets, veh, brk)
    ego_agent = next(a for a in gts[0].agents if a.kind == 0)
    first_peds = [a for a in gts[0].agents if a.kind == 2]
    peds = (np.array([[[a.pose.x, a.pose.y] for a in g.agents if a.kind == 2] for g in gts]).reshape(
                len(gts), len(first_peds), 2),
            np.array([a.radius for a in first_peds]), np.array([a.id for a in first_peds], dtype=np.int64))
    state, m = metrics_from_log(lot, float(status.dt), float(status.t_final), (ego_agent.length, ego_agent.width),
                                ego, veh, dims, ids, dynamic, targets, brk, peds)
    names = {0: "idle", 1: "running", 2: "success", 3: "collision", 4: "timeout"}
    recomputed = {"state": state, **{k: nan_to_none(v) for k, v in m.as_dict().items()}}
    kind, _, ident = recomputed["collision_with"].partition(":")
    if kind == "vehicle" and int(ident or 0) > DRIVEN_ID:  # the name the simulator gives a driven car
        recomputed["collision_with"] = f"driver:{int(ident) - DRIVEN_ID - 1}"
    lm = status.metrics
    live = {"state": names[int(status.state)], "success": bool(lm.success), "collision": bool(lm.collision),
            "collision_with": lm.collision_with, "collision_at_fault": bool(lm.collision_at_fault),
            "spot_stolen": bool(lm.spot_stolen),
            "parked_spot_id": int(lm.parked_spot_id), "interrupted_steps": int(lm.interrupted_steps),
            "interrupted_agent_steps": int(lm.interrupted_agent_steps),
            "parking_time": nan_to_none(float(lm.parking_time)), "steps": int(lm.steps)}
    return recomputed, live


def ego_metrics_from_bag(bag: Path, ego: int, driver: bool = False) -> dict:
    """Several egos (``avp demo --egos K``): ego ``ego``'s state and metrics as the simulator published them live on
    ``/avp/ego<i>/episode_status`` (the last episode), and the steps it was in the lot per the ground truth. The
    independent recomputation of :func:`metrics_from_bag` covers the one-ego graph only (docs/world.md). ``driver``:
    driven car ``ego``'s record (``/avp/driver<j>/episode_status``: the agents it made brake, its collisions)."""
    from avp_sim.core.metrics import nan_to_none

    topic = f"/avp/{'driver' if driver else 'ego'}{int(ego)}/episode_status"
    kind = 3 if driver else 0
    reader = BagReader(bag)
    status, steps = None, set()
    for t, msgtype, _t, raw in reader.messages((topic, "/avp/debug/ground_truth")):
        msg = reader.deserialize(raw, msgtype)
        if t == topic:
            status = msg
        else:
            if int(msg.step) == 0:
                steps = set()
            if any(a.kind == kind and int(a.id) == ego for a in msg.agents):
                steps.add(int(msg.step))
    if status is None:
        raise ValueError(f"{bag}: no {topic} messages (a bag of avp demo --egos K or --drive?)")
    names = {0: "idle", 1: "running", 2: "success", 3: "collision", 4: "timeout"}
    lm = status.metrics
    return {"driver" if driver else "ego": ego, "state": names[int(status.state)], "success": bool(lm.success),
            "collision": bool(lm.collision),
            "collision_with": lm.collision_with, "collision_at_fault": bool(lm.collision_at_fault),
            "spot_stolen": bool(lm.spot_stolen), "parked_spot_id": int(lm.parked_spot_id),
            "interrupted_steps": int(lm.interrupted_steps), "interrupted_agent_steps": int(lm.interrupted_agent_steps),
            "parking_time": nan_to_none(float(lm.parking_time)), "steps": int(lm.steps),
            "steps_in_the_lot": len(steps), "entered_step": min(steps) if steps else None}
