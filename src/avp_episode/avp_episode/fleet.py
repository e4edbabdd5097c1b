"""Several automated cars in one lot, in process: K egos, each a pipeline of its own (a :class:`~.ego.MethodEgo`
of its method), on one simulator core (:mod:`avp_sim.core.egos`). No ego is told another's plan or chosen spot; to
each the others are observed vehicles.

One record per ego-episode: the §VI-B record of :func:`~.metrics.episode_record` for that ego, plus its index, the
fleet, its entry time, the spots it lost (to an agent or to another ego, counted apart) and the episode's gridlock
(:mod:`.gridlock`). A spot is *lost* when the spot an ego is driving to park in (its decision's target, taken when
the spot was free) is taken by another vehicle (an agent or ego that comes to lie inside it) before the ego parks
there. The first fleet records (docs/results/fleet/README.md) also counted a target that another vehicle already lay
in, once per decision: for them, count the episodes with a loss, not the losses.
"""

from __future__ import annotations

import time

import numpy as np

from avp_episode.fleet_metrics import SpotLosses, holders_of, trace_wait, wait_edges
from avp_episode.gridlock import GridlockMeter, Node
from avp_episode.profiles import MethodProfile
from avp_episode.run_config import ORACLE_HORIZON, RunConfig

#: s without a decision after which the reservation book frees an ego's spot (avp_planner.core.reservation); in
#: process every driving ego decides every step, so only a finished ego's hold ends, and at once
RESERVATION_TIMEOUT = 5.0
#: the method field of a fleet's records (and of its episode keys): ``fleet:`` + its methods in ego order
FLEET_PREFIX = "fleet:"


def fleet_label(names: list[str]) -> str:
    return FLEET_PREFIX + ",".join(names)


def fleet_names(label: str) -> list[str]:
    """The methods of a fleet label, ego by ego ([] for a plain method name)."""
    return label[len(FLEET_PREFIX):].split(",") if label.startswith(FLEET_PREFIX) else []


def run_units(methods: list[str], egos: int, fleet: str) -> list[str]:
    """What the episode keys name: the methods themselves (one ego), a fleet of ``egos`` of each method, or the one
    mixed ``fleet``."""
    if fleet:
        return [fleet_label(parse_fleet(fleet, egos if egos > 1 else None))]
    if egos == 1:
        return list(methods)
    return [fleet_label(parse_fleet(m, egos)) for m in methods]


def parse_fleet(spec: str, egos: int | None = None, option: str = "--fleet") -> list[str]:
    """``bezier,bezier,blind`` -> one method per ego; ``bezier`` with ``egos`` = K -> K of it. One clear error for a
    malformed spec, naming ``option``."""
    names = [s.strip() for s in spec.split(",")] if spec else []
    if not names or any(not n for n in names):
        raise ValueError(f"{option}: expected comma-separated method names, got {spec!r}")
    if egos is not None:
        if not 1 <= egos <= 8:
            raise ValueError(f"--egos: expected 1..8 automated cars, got {egos}")
        if len(names) == 1:
            names = names * egos
        elif len(names) != egos:
            raise ValueError(f"{option} names {len(names)} methods but --egos is {egos}")
    if not 1 <= len(names) <= 8:
        raise ValueError(f"{option}: 1..8 egos, got {len(names)}")
    return names


def _holders(world) -> dict[int, str]:
    """Spot id -> "agent" or "ego:<j>" for every spot a vehicle or ego lies inside now (§III-A's rule)."""
    rows = np.nonzero(world.egos.present)[0]
    return holders_of(world.lot, world.occupancy_with(rows)[1], len(world.states), rows)


def waits_for(world, decisions: dict[int, object]) -> dict[Node, set[Node]]:
    """This step's waits-for edges (:mod:`.gridlock`): egos standing for the agent their trace names, agents braking
    for an ego."""
    from avp_motion.trace import step_of
    from avp_sim.core.egos import EGO_ID_BASE

    waits = []
    for i, d in decisions.items():
        _, tr, still = step_of(d)
        a = trace_wait(still, tr.get("agent_id"), bool(tr.get("pedestrian")))
        if a is not None:
            waits.append((i, a))
    rows, egos = np.nonzero(world.braking_for)
    return wait_edges(waits, ((int(world.vehicle_ids[r]), int(j)) for r, j in zip(rows, egos, strict=True)),
                      EGO_ID_BASE)


def run_fleet_inproc(lot, sim_p: dict, profiles: list[MethodProfile], seed: int, reactive: bool,
                     cfg: RunConfig, scenario: tuple[str, dict] | None = None, keep: dict | None = None) -> list[dict]:
    """One episode with ``len(profiles)`` egos (``egos.count`` is set to it; ``scenario``: (name, the parsed scenario
    file) instead of the seed's scenario, its ``egos`` one fewer than the profiles); a record per ego. ``keep``: a
    dict that receives the finished ``world`` (a test's oracle)."""
    from avp_episode.ego import MethodEgo
    from avp_episode.metrics import episode_record, lot_record
    from avp_episode.oracle import OracleEgo, ground_truth
    from avp_motion.trace import DecisionTrace
    from avp_planner.core.ego_yield import beacon_of, with_beacons
    from avp_planner.core.reservation import SpotReservations
    from avp_sim.core.factory import make_world

    t0 = time.perf_counter()
    k = len(profiles)
    world = make_world(lot, dict(sim_p, **{"egos.count": k}), seed, reactive, scenario_data=scenario)
    if world.egos.count != k:
        raise ValueError(f"the scenario has {world.egos.count} egos, the fleet {k}")
    egos = [(OracleEgo if p.ground_truth else MethodEgo)(
        lot, p, deterministic=True, intent_weights=cfg.intent_weights, intent_seed=cfg.intent_seed,
        message_precision=cfg.message_precision) for p in profiles]
    traces = [DecisionTrace(world.dt) for _ in range(k)]
    reserve = [p.coordination == "reserve" for p in profiles]
    book = SpotReservations(RESERVATION_TIMEOUT) if any(reserve) else None
    timings: list[list[dict]] = [[] for _ in range(k)]
    losses = SpotLosses(k)  # the spot each ego is driving to park in, and the spots it lost
    meter = GridlockMeter(world.dt)
    holders: dict[int, str] = _holders(world)
    beacons: list = []  # what the egos announced at the step before (avp_planner.core.ego_yield)
    while not world.done:
        driving = world.egos.driving.copy()
        commands, decisions, claims, sent = [], {}, {}, []
        for i in range(k):
            if not driving[i]:
                commands.append((0.0, 0.0))
                continue
            if profiles[i].ground_truth:  # the oracle bound: told the agents' true futures (not the other egos')
                egos[i].tell(ground_truth(world, ORACLE_HORIZON))
            obs = world.observe(i)
            if book is not None and reserve[i]:  # the spots other egos hold, shown as occupied (.reservation)
                obs = book.apply(obs, i)
            obs = with_beacons(obs, beacons, i)  # the fleet's channel: what egos before it sent the step before
            out = egos[i].step(obs)
            if book is not None and reserve[i]:
                claims[i] = out.decision
            commands.append(out.command)
            timings[i].append(out.timings)
            if out.decision is not None:
                traces[i].add(out.step, out.decision)
                decisions[i] = out.decision
                sent.append(beacon_of(i, obs.ego_pose, out.decision))
                losses.decided(i, out.decision.mode == "park", int(out.decision.spot_id), holders)
        if book is not None:  # after every ego decided: the next step's holds (SpotReservations.settle)
            book.settle(claims, world.step_index * world.dt)
        beacons = sent
        meter.add(world.step_index, waits_for(world, decisions))
        world.step_all(commands)
        if book is not None:
            for i in np.nonzero(driving & ~world.egos.driving)[0]:  # parked, crashed or timed out: its hold ends
                book.release(int(i))
        holders = _holders(world)
        losses.stepped(holders)
    grid = meter.summary(world.step_index)
    wall = time.perf_counter() - t0
    if keep is not None:
        keep["world"] = world
    fleet = ",".join(p.name for p in profiles)
    label = fleet_label([p.name for p in profiles])
    records = []
    for i in range(k):
        entered = int(world.egos.entered_step[i])
        rec = episode_record(method=profiles[i].name, seed=seed, reactive=reactive, status=world.egos.status[i],
                             metrics=world.egos.metrics[i].as_dict(), min_ade=np.zeros(0), min_fde=np.zeros(0),
                             step_timings=timings[i], horizon=cfg.ade_horizon, transport="inproc", wall_s=wall,
                             lot=lot_record(lot),
                             ego_poses=np.asarray(world.log_egos)[entered:, i] if entered >= 0 else np.zeros((0, 3)),
                             decision_trace=traces[i].summary())
        rec.update(method=label, ego_method=profiles[i].name, ego=i, egos=k, fleet=fleet,
                   episode_s=round(world.step_index * world.dt, 3),
                   entered_s=None if entered < 0 else round(entered * world.dt, 3),
                   final_pose=None if entered < 0 else [round(float(x), 6) for x in world.egos.poses[i]],
                   spots_lost_to_agent=losses.lost[i]["agent"], spots_lost_to_ego=losses.lost[i]["ego"], **grid)
        records.append(rec)
    return records


def fleet_table(records: list[dict]) -> str:
    """The fleet columns of docs/metrics.md ("Several egos") per fleet and mode, as a Markdown table: ego-episodes,
    success with its 95 % Wilson interval, collisions (at fault; with another ego), spots lost to an ego / an agent,
    episodes with a gridlock, mean parking time, lot throughput (egos parked per minute of simulated time)."""
    from avp_episode.metrics import wilson

    rows = ["| fleet | mode | ego-episodes | success [95 % CI] | collisions (at fault) | ego-ego collisions | "
            "spots lost to an ego / an agent | episodes with a gridlock | mean parking time s | egos parked per min |",
            "|---|---|--:|---|---|--:|---|---|--:|--:|"]
    groups: dict[tuple[str, str], list[dict]] = {}
    for r in records:
        if r.get("egos"):
            groups.setdefault((r["method"], r["mode"]), []).append(r)
    for (label, mode), rs in sorted(groups.items()):
        n, ok = len(rs), sum(r["success"] for r in rs)
        lo, hi = wilson(ok, n)
        episodes: dict[int, list[dict]] = {}
        for r in rs:
            episodes.setdefault(r["seed"], []).append(r)
        grid = sum(any(r["gridlock"] for r in ep) for ep in episodes.values())
        minutes = sum(ep[0]["episode_s"] for ep in episodes.values()) / 60.0
        times = [r["parking_time"] for r in rs if r["success"] and r["parking_time"] is not None]
        rows.append(
            f"| {label[len(FLEET_PREFIX):]} | {mode} | {n} | {ok} = {100 * ok / n:.1f} % [{100 * lo:.1f}, "
            f"{100 * hi:.1f}] | {sum(r['collision'] for r in rs)} ({sum(r['collision_at_fault'] for r in rs)}) | "
            f"{sum(r['collision_with'].startswith('ego:') for r in rs)} | "
            f"{sum(r['spots_lost_to_ego'] for r in rs)} / {sum(r['spots_lost_to_agent'] for r in rs)} | "
            f"{grid} of {len(episodes)} | {sum(times) / len(times) if times else float('nan'):.1f} | "
            f"{ok / minutes if minutes else float('nan'):.2f} |")
    return "\n".join(rows)
