"""``agents_yield`` (avp_sim/core/agent_yield.py): agents that also brake for each other, on hand-built episodes.

Off (§III-B, the paper) a car drives through a car that stands for the ego, and through a pedestrian; on, it waits
behind it and lets the pedestrian cross. Shapely judges every overlap; braking for another agent must not count as
interrupted by the ego (§VI-B).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from shapely.geometry import Point, Polygon

from avp_scenario.scenario import PedestrianAgent, Scenario, VehicleAgent
from avp_sensing.observation import SensorConfig
from avp_sim.core.world import World, WorldConfig
from avp_world.geometry import rect_corners
from avp_world.vehicle import VehicleSpec

EGO = VehicleSpec()
SOUTH = -math.pi / 2


def _car(agent_id, at_t0, speed, passiveness, n_steps=200, hist=40):
    init = np.array([at_t0[0], at_t0[1] + speed * hist * 0.1, SOUTH])  # driving south down the middle road
    return VehicleAgent(id=agent_id, length=4.6, width=1.85, initial_state=init,
                        controls=np.tile([speed, 0.0], (hist + n_steps, 1)), passiveness=passiveness)


def _walker(ped_id, at_t0, speed, passiveness, n_steps=200, hist=40):
    init = np.array([at_t0[0] - speed * hist * 0.1, at_t0[1]])  # walking east across the middle road
    return PedestrianAgent(id=ped_id, radius=0.3, initial_position=init,
                           controls=np.tile([speed, 0.0], (hist + n_steps, 1)), passiveness=passiveness)


def _run(lot, ego_start, vehicles, pedestrians=(), yield_=False, t_final=12.0):
    sc = Scenario(seed=0, reactive=True, ego_start=np.array(ego_start, float), ego=EGO, vehicles=tuple(vehicles),
                  pedestrians=tuple(pedestrians))
    w = World(lot, sc, WorldConfig(t_final=t_final, sensor=SensorConfig(), agents_yield=yield_))
    frames = []
    while not w.done:
        w.step(0.0, 0.0)  # the ego stands
        frames.append((w.states.copy(), w.ped_pos.copy(), w.braking.copy(), w.yielding.copy(), w.ped_yielding.copy()))
    return w, frames


def _car_overlap(states, i, k):
    a, b = (Polygon(rect_corners(states[j], 4.6, 1.85)) for j in (i, k))
    return a.intersection(b).area


@pytest.mark.parametrize("yield_", [False, True])
def test_a_car_behind_one_that_stands_for_the_ego_drives_through_it_unless_agents_yield(paper_lot, yield_):
    # the ego stands in the middle road facing north; car 1 comes down the road and stops for it, car 2 follows faster
    cars = [_car(1, (21.5, 26.0), 1.0, 3), _car(2, (21.5, 34.0), 2.0, 3)]
    w, frames = _run(paper_lot, (21.5, 14.0, math.pi / 2), cars, yield_=yield_)
    worst = max(_car_overlap(s, 0, 1) for s, *_ in frames)
    stood_for_ego = sum(int(b[0]) + int(b[1]) for _, _, b, _, _ in frames)
    if not yield_:
        assert worst > 5.0  # car 2 ends up on top of car 1
        return
    assert worst == 0.0
    assert frames[-1][0][1, 1] - frames[-1][0][0, 1] > 4.6  # car 2 waits behind car 1, more than a length back
    assert any(y[1] for *_, y, _ in frames) and not any(y[0] for *_, y, _ in frames)
    assert not any((b & y).any() for _, _, b, y, _ in frames)  # braking for the ego and yielding are apart
    assert w.metrics.interrupted_agent_steps == stood_for_ego  # only braking for the ego counts (§VI-B)
    assert all(not b[1] for _, _, b, _, _ in frames)  # car 2 never reaches the ego: it never brakes for it


@pytest.mark.parametrize("yield_", [False, True])
def test_a_car_lets_a_pedestrian_cross_when_agents_yield(paper_lot, yield_):
    # car 1 drives down the middle road at 2 m/s; a pedestrian crosses it at 1 m/s and both reach y = 24 at t = 4 s
    w, frames = _run(paper_lot, (3.5, 20.0, SOUTH), [_car(1, (21.5, 32.0), 2.0, 3)], [_walker(7, (17.5, 24.0), 1.0, 3)],
                     yield_=yield_)
    worst = max(Polygon(rect_corners(s[0], 4.6, 1.85)).intersection(Point(*p[0]).buffer(0.3)).area
                for s, p, *_ in frames)
    if not yield_:
        assert worst > 0.1
        return
    assert worst == 0.0
    car_y, ped_x = frames[-1][0][0, 1], frames[-1][1][0, 0]
    assert car_y < 24.0 - 4.6 and ped_x > 21.5 + 2.0  # both went past the crossing: nobody waits for good
    assert any(y[0] for *_, y, _ in frames) or any(py[0] for *_, py in frames)
    assert w.metrics.interrupted_agent_steps == 0  # the ego stood on the left road, out of everyone's way


def test_two_cars_that_each_meet_the_other_do_not_wait_for_good(paper_lot):
    # head-on in one lane: each one's look-ahead meets the other; the first in the scenario drives on, so they
    # cannot both stand (they then overlap: a head-on in one lane has no way round, and the rule does not steer)
    a = _car(1, (21.5, 30.0), 1.0, 3)
    b = VehicleAgent(id=2, length=4.6, width=1.85, initial_state=np.array([21.5, 20.0 - 4.0, math.pi / 2]),
                     controls=np.tile([1.0, 0.0], (240, 1)), passiveness=3)
    w, frames = _run(paper_lot, (3.5, 20.0, SOUTH), [a, b], yield_=True, t_final=6.0)
    assert not any(y[0] for *_, y, _ in frames)  # car 1 never yields
    assert any(y[1] for *_, y, _ in frames)  # car 2 does
    assert frames[-1][0][0, 1] < 30.0 - 5.0  # car 1 kept going
