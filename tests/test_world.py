"""World stepping on hand-built episodes: reactive braking (§III-B) and the §VI-B metric definitions.

Oracles: shapely for footprints/containment, closed-form straight-line motion for positions.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from shapely.geometry import Polygon

from avp_scenario.scenario import Scenario, VehicleAgent
from avp_sensing.observation import SensorConfig
from avp_sim.core.world import COLLISION, SUCCESS, TIMEOUT, World, WorldConfig
from avp_world.geometry import rect_corners
from avp_world.vehicle import VehicleSpec

EGO = VehicleSpec()


def _straight_agent(agent_id, start_t0, heading, speed, n_steps, passiveness, hist=40, target=-1):
    """An agent that drives straight at ``speed`` for ``hist`` steps before t = 0 and ``n_steps`` after."""
    d = np.array([math.cos(heading), math.sin(heading)])
    init = np.array([*(np.asarray(start_t0) - d * speed * hist * 0.1), heading])
    controls = np.tile([speed, 0.0], (hist + n_steps, 1))
    return VehicleAgent(id=agent_id, length=4.6, width=1.85, initial_state=init, controls=controls,
                        passiveness=passiveness, target_spot_id=target)


def _world(lot, ego_start, vehicles, t_final=30.0):
    sc = Scenario(seed=0, reactive=True, ego_start=np.array(ego_start, float), ego=EGO, vehicles=tuple(vehicles))
    return World(lot, sc, WorldConfig(t_final=t_final, sensor=SensorConfig()))


def _poly(pose, length=4.6, width=1.85):
    return Polygon(rect_corners(np.asarray(pose), length, width))


def test_history_exists_at_t0(paper_lot):
    a = _straight_agent(1000, (21.5 - 1.75, 30.0), -math.pi / 2, 1.0, 50, 0)
    w = _world(paper_lot, (21.5, 38.0, -math.pi / 2), [a])
    assert w.history.shape == (1, 41, 3)
    # 4 s of history: straight line at 1 m/s ending at the t = 0 position
    assert np.allclose(w.history[0, -1, :2], [19.75, 30.0])
    assert np.allclose(w.history[0, 0, :2], [19.75, 34.0])


def test_reactive_agent_brakes_for_ego_and_resumes(paper_lot):
    # agent drives south in the middle road towards an ego standing across its lane
    n_pass = 3
    a = _straight_agent(1000, (21.5, 30.0), -math.pi / 2, 1.0, 200, n_pass)
    ego_start = (21.5, 20.0, 0.0)
    w = _world(paper_lot, ego_start, [a], t_final=60.0)
    stopped_gap = None
    for k in range(150):  # ego waits 12 s, then drives east out of the lane
        v = 0.0 if k < 120 else 2.0
        w.step(v, 0.0)
        assert w.status != COLLISION
        if k == 110:
            assert w.braking[0], "agent should be braking while the ego blocks its lane"
            stopped_gap = _poly(w.states[0]).distance(_poly(w.ego))
    assert stopped_gap is not None and 0.0 < stopped_gap <= n_pass * 1.0 * 0.1 + 1e-9
    braked = np.array(w.log_braking)[:, 0]
    assert w.metrics.interrupted_steps == int(braked.sum()) > 0
    # it resumed its plan where it left it: 200 planned steps at 1 m/s, none skipped
    while not w.done and w.step_index < 400:
        w.step(0.0, 0.0)
    executed = int(w.plan_index[0])
    assert executed == 40 + (w.step_index - int(braked.sum()))
    expected_y = 30.0 - min(executed - 40, 200) * 0.1 * 1.0  # plan ends after 200 steps
    assert math.isclose(w.states[0, 1], expected_y, abs_tol=1e-9)


def test_non_reactive_agent_collides_with_a_standing_ego(paper_lot):
    a = _straight_agent(1007, (21.5, 30.0), -math.pi / 2, 1.0, 200, 0)
    w = _world(paper_lot, (21.5, 20.0, 0.0), [a])
    while not w.done:
        w.step(0.0, 0.0)
    assert w.status == COLLISION and w.metrics.collision_with == "vehicle:1007"
    assert not w.metrics.success and w.metrics.interrupted_steps == 0
    # collision happens at the first step where the shapely footprints meet
    first = next(k for k, s in enumerate(w.log_vehicles) if _poly(s[0]).intersects(_poly(w.ego)))
    assert w.step_index == first


def test_parking_success_time_and_stolen(paper_lot):
    spot = paper_lot.spots[paper_lot.spot_index(20)]  # column 2, faces east, centre (27.75, 8.375)
    # a dynamic vehicle far away whose plan targets spot 20
    a = _straight_agent(1001, (3.5 + 1.75, 20.0), math.pi / 2, 0.0, 10, 2, target=20)
    w = _world(paper_lot, (24.0, spot.y, 0.0), [a])
    while not w.done:
        w.step(1.0, 0.0)
    spot_poly = Polygon(paper_lot.spot_corners[paper_lot.spot_index(20)])
    first_inside = next(k for k, e in enumerate(w.log_ego) if _poly(e).within(spot_poly))
    assert w.status == SUCCESS and w.metrics.success
    assert w.metrics.parked_spot_id == 20 and w.metrics.spot_stolen
    assert math.isclose(w.metrics.parking_time, first_inside * 0.1)


def test_parking_elsewhere_is_not_stolen(paper_lot):
    a = _straight_agent(1001, (3.5 + 1.75, 20.0), math.pi / 2, 0.0, 10, 2, target=21)
    w = _world(paper_lot, (24.0, paper_lot.spots[20].y, 0.0), [a])
    while not w.done:
        w.step(1.0, 0.0)
    assert w.metrics.success and not w.metrics.spot_stolen


def test_boundary_collision_and_timeout(paper_lot):
    w = _world(paper_lot, (4.05, 20.0, math.pi), [])  # not exactly touching at any step
    while not w.done:
        w.step(1.0, 0.0)
    assert w.status == COLLISION and w.metrics.collision_with == "boundary"
    # first step at which the footprint leaves L (shapely oracle)
    lot_poly = Polygon(paper_lot.boundary)
    first_out = next(k for k, e in enumerate(w.log_ego) if not _poly(e).within(lot_poly))
    assert w.step_index == first_out
    w = _world(paper_lot, (21.5, 30.0, 0.0), [], t_final=2.0)
    while not w.done:
        w.step(0.0, 0.0)
    assert w.status == TIMEOUT and w.step_index == 20 and not w.metrics.success


def test_ego_command_clipped_to_car_limits(paper_lot):
    w = _world(paper_lot, (21.5, 30.0, -math.pi / 2), [])
    assert w.clip_command(9.0, 0.0) == (5.0, 0.0)
    v, om = w.clip_command(1.0, 5.0)
    assert v == 1.0 and math.isclose(om, 1.0 / EGO.min_turning_radius)
    assert w.clip_command(0.0, 1.0) == (0.0, 0.0)  # a car cannot turn on the spot


def test_metrics_recomputed_from_logged_ground_truth_equal_live(paper_lot):
    from avp_sim.core.metrics import metrics_from_log

    n_pass = 3
    a = _straight_agent(1000, (21.5, 30.0), -math.pi / 2, 1.0, 200, n_pass)
    w = _world(paper_lot, (21.5, 20.0, 0.0), [a], t_final=40.0)
    for k in range(400):
        w.step(0.0 if k < 120 else 2.0, 0.0 if k < 150 else -0.2)
        if w.done:
            break
    status, m = metrics_from_log(paper_lot, 0.1, 40.0, (4.6, 1.85), np.array(w.log_ego), np.array(w.log_vehicles),
                                 w.vehicle_dims, w.vehicle_ids, w.is_dynamic, w.target_spot, np.array(w.log_braking))
    assert status == w.status
    assert m.as_dict() == pytest.approx(w.metrics.as_dict(), nan_ok=True)
    assert m.interrupted_steps > 0


def test_reactive_brakes_skip_only_agents_that_cannot_reach_the_ego(paper_lot):
    """The reach bound (circumradii + the farthest an agent's plan carries it in n_pass steps) only skips work:
    brakes equal those of the full check (every agent rolled out) at every step of paper-protocol episodes
    in which the ego drives through the agents."""
    from pathlib import Path

    import avp_sim.params
    from avp_common.params import load_yaml_params
    from avp_sim.core.factory import make_world

    cfg = Path(__file__).resolve().parents[1] / "src/avp_sim/config/sim.param.yaml"
    p = load_yaml_params(cfg, "avp_sim", avp_sim.params.SIM_PARAMS)
    n_braking = 0
    for seed in (1, 3, 5):
        w = make_world(paper_lot, p, seed, True)
        full = make_world(paper_lot, p, seed, True)
        full._brake_reach = np.full_like(full._brake_reach, np.inf)
        for k in range(250):
            cmd = (2.0, 0.0) if k % 80 < 40 else (2.0, 0.15)
            b, pb, _ = w._reactive_brakes()
            bf, pbf, _ = full._reactive_brakes()
            assert np.array_equal(b, bf) and np.array_equal(pb, pbf), (seed, k)
            n_braking += int(b.any())
            w.step(*cmd)
            full.step(*cmd)
            if w.done:
                break
    assert n_braking > 0  # the comparison covered steps where agents do brake


def _walker(ped_id, start, heading, speed, n_steps, hist=40):
    from avp_scenario.scenario import PedestrianAgent

    d = np.array([math.cos(heading), math.sin(heading)])
    init = np.asarray(start, float) - d * speed * hist * 0.1
    return PedestrianAgent(id=ped_id, radius=0.3, initial_position=init,
                           controls=np.tile([speed, heading], (hist + n_steps, 1)))


@pytest.mark.parametrize("ego_moves", [False, True])
def test_pedestrian_collisions_are_counted_with_who_was_at_fault(paper_lot, ego_moves):
    """A pedestrian walking into a standing ego is a collision the ego is not at fault for; the ego
    driving into a standing pedestrian is. The recomputation from the logged ground truth agrees."""
    from avp_sim.core.metrics import metrics_from_log

    if ego_moves:  # the pedestrian stands 4 m ahead of the ego in the middle road; the ego drives at it
        ped = _walker(20000, (21.5, 26.0), 0.0, 0.0, 200)
    else:  # the pedestrian crosses the road through the standing ego
        ped = _walker(20000, (17.0, 30.0), 0.0, 1.0, 200)
    sc = Scenario(seed=0, reactive=False, ego_start=np.array([21.5, 30.0, -math.pi / 2]), ego=EGO, vehicles=(),
                  pedestrians=(ped,))
    w = World(paper_lot, sc, WorldConfig(t_final=30.0, sensor=SensorConfig()))
    peds = [w.ped_pos.copy()]
    while not w.done:
        w.step(1.0 if ego_moves else 0.0, 0.0)
        peds.append(w.ped_pos.copy())
    assert w.status == COLLISION and w.metrics.collision_with == "pedestrian:20000"
    assert w.metrics.collision_at_fault == ego_moves
    z = np.zeros((len(w.log_ego), 0, 3))
    state, m = metrics_from_log(paper_lot, 0.1, 30.0, (EGO.length, EGO.width), np.array(w.log_ego), z,
                                np.zeros((0, 2)), np.zeros(0, np.int64), np.zeros(0, bool), np.zeros(0, np.int64),
                                np.zeros((len(w.log_ego), 0), bool), (np.array(peds), w.ped_radii, w.ped_ids))
    assert state == COLLISION and m.as_dict() == w.metrics.as_dict()
