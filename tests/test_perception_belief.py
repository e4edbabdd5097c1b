"""Belief map of §V-B: eq. (7) (observation update) and eq. (8) (intention update).

Expected values are worked out by hand from the equations; none come from the code under test.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from avp_belief_map.belief import BELIEF_INIT, BeliefMap, intention_update, observation_update, spot_indices
from avp_predictors.intention import Intention, split_none_mass
from avp_scenario.scenario import ScenarioParams, generate_paper_scenario
from avp_sim.core.world import World


def test_initial_belief_is_one_half():
    bm = BeliefMap(5)
    assert BELIEF_INIT == 0.5
    np.testing.assert_array_equal(bm.values, [0.5] * 5)
    np.testing.assert_array_equal(BeliefMap(3, init=0.2).values, [0.2] * 3)


def test_eq7_vacant_zero_occupied_one_unobserved_kept():
    prev = np.array([0.5, 0.2, 0.9, 0.7, 0.35])
    b = observation_update(prev, vacant_idx=[1, 4], occupied_idx=[0])
    np.testing.assert_array_equal(b, [1.0, 0.0, 0.9, 0.7, 0.0])
    np.testing.assert_array_equal(prev, [0.5, 0.2, 0.9, 0.7, 0.35])  # input untouched


def test_eq8_noisy_or_over_vehicles_on_observed_vacant_spots_only():
    # spots: 0, 1 observed vacant; 2 observed occupied; 3, 4 unobserved
    b_tilde = np.array([0.0, 0.0, 1.0, 0.5, 0.2])
    vac = [0, 1]
    # vehicle A: candidates 0 (0.6), 1 (0.1), 4 (0.3, unobserved: eq. 8 leaves it alone); vehicle B: 0 (0.5)
    b = intention_update(b_tilde, vac, [np.array([0, 1, 4]), np.array([0])],
                         [np.array([0.6, 0.1, 0.3]), np.array([0.5])])
    expected = [1 - (1 - 0.6) * (1 - 0.5), 0.1, 1.0, 0.5, 0.2]  # = [0.8, 0.1, 1, 0.5, 0.2]
    np.testing.assert_allclose(b, expected, atol=1e-12)
    assert b[0] == pytest.approx(0.8)


def test_eq8_vacant_spot_of_nobody_stays_zero_and_no_vehicles_is_identity():
    b_tilde = np.array([0.0, 0.0, 0.6])
    b = intention_update(b_tilde, [0, 1], [np.array([1])], [np.array([0.25])])
    np.testing.assert_allclose(b, [0.0, 0.25, 0.6])
    np.testing.assert_array_equal(intention_update(b_tilde, [0, 1], [], []), b_tilde)


def test_eq8_rejects_mismatched_inputs():
    with pytest.raises(ValueError):
        intention_update(np.zeros(3), [0], [np.array([0, 1])], [np.array([0.5])])
    with pytest.raises(ValueError):
        intention_update(np.zeros(3), [0], [np.array([0])], [])


def test_belief_map_over_steps_with_spot_ids():
    bm = BeliefMap(4, spot_ids=np.array([10, 20, 30, 40]))
    # step 0: 20 seen vacant, 30 seen occupied; vehicle 7 wants 20 with 0.7 and 40 (unobserved) with 0.2
    bt = bm.observe([20], [30])
    np.testing.assert_array_equal(bt, [0.5, 0.0, 1.0, 0.5])
    it = Intention(7, np.array([20, 40]), np.array([0.7, 0.2]), none_probability=0.1)
    np.testing.assert_allclose(bm.apply_intentions([it]), [0.5, 0.7, 1.0, 0.5])
    np.testing.assert_array_equal(bm.b_tilde, [0.5, 0.0, 1.0, 0.5])  # b~ kept for the BEV
    np.testing.assert_array_equal(bm.observed_mask, [False, True, True, False])
    # step 1: nothing observed -> b~ = b_{t-dt}; no intentions -> unchanged
    np.testing.assert_allclose(bm.observe([], []), [0.5, 0.7, 1.0, 0.5])
    np.testing.assert_allclose(bm.apply_intentions([]), [0.5, 0.7, 1.0, 0.5])
    # step 2: 20 is seen occupied now, 30 vacant again and wanted by two vehicles
    bm.observe([30], [20])
    b = bm.apply_intentions([Intention(7, np.array([30]), np.array([0.5])),
                             Intention(8, np.array([30]), np.array([0.4]))])
    np.testing.assert_allclose(b, [0.5, 1.0, 1 - 0.5 * 0.6, 0.5])
    with pytest.raises(KeyError, match="99"):
        bm.observe([99], [])
    bm.reset()
    np.testing.assert_array_equal(bm.values, [0.5] * 4)


def test_belief_map_from_world_observation(paper_lot):
    params = replace(ScenarioParams(), ego_start=(21.5, 20.0, -math.pi / 2), n_dynamic=(2, 2))
    world = World(paper_lot, generate_paper_scenario(paper_lot, 0, True, params))
    obs = world.observe()
    bm = BeliefMap.from_lot(paper_lot)
    bt = bm.observe(obs.vacant_spot_ids, obs.occupied_spot_ids)
    vac = spot_indices(paper_lot, obs.vacant_spot_ids)
    occ = spot_indices(paper_lot, obs.occupied_spot_ids)
    assert len(vac) and len(occ)
    assert np.all(bt[vac] == 0.0) and np.all(bt[occ] == 1.0)
    rest = np.setdiff1d(np.arange(paper_lot.n_spots), np.concatenate([vac, occ]))
    assert len(rest) and np.all(bt[rest] == 0.5)


def test_none_mass_split_as_parkpredict():
    np.testing.assert_allclose(split_none_mass(0.3, 5), 0.3 * np.array([0.9, 0.5, 0.1]) / 1.5)
    np.testing.assert_allclose(split_none_mass(0.3, 3), [0.18, 0.1, 0.02])
    np.testing.assert_allclose(split_none_mass(0.4, 1), [0.4])
    np.testing.assert_allclose(split_none_mass(0.4, 2), [0.36, 0.04])
    assert split_none_mass(0.4, 0).shape == (0,)
