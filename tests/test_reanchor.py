"""``decision.replan_pose_sigmas``: a driven plan the drifting pose estimate is off by a little is moved onto the
estimate and kept (avp_motion.reanchor); the paper's planner (k = 0), exact sensing (no covariance) and a drift
beyond k standard deviations search again."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from test_planner_decision import make_obs
from unhurried import unhurried

from avp_motion.reanchor import follow_tolerance, reanchored
from avp_planner.core.decision import EgoPlanner

COV = np.diag([0.15**2, 0.10**2, 0.025**2])  # a localiser's covariance: σ 0.15 / 0.10 m, 0.025 rad


def test_reanchored_moves_the_rest_rigidly_onto_the_pose():
    rng = np.random.default_rng(3)
    states = np.cumsum(rng.normal(0, 0.3, (30, 3)), axis=0)
    pose = states[12] + np.array([0.08, -0.05, 0.03])
    out = reanchored(states, 12, pose)
    assert np.allclose(out[:12], states[:12])  # the states driven are kept
    assert np.allclose(out[12], pose)
    # a rigid motion: every distance between the moved states and every heading difference is kept
    d_in = np.linalg.norm(states[12:, None, :2] - states[None, 12:, :2], axis=-1)
    d_out = np.linalg.norm(out[12:, None, :2] - out[None, 12:, :2], axis=-1)
    assert np.allclose(d_in, d_out)
    turn = np.angle(np.exp(1j * (out[12:, 2] - states[12:, 2])))
    assert np.allclose(turn, 0.03)


def test_follow_tolerance_is_k_sigmas_never_below_the_plans_own():
    assert follow_tolerance(None, 2.0, 0.05) == (0.05, 0.02)
    assert follow_tolerance(COV, 0.0, 0.05) == (0.05, 0.02)
    xy, th = follow_tolerance(COV, 2.0, 0.05)
    assert xy == pytest.approx(0.30) and th == pytest.approx(0.05)
    assert follow_tolerance(COV * 1e-4, 2.0, 0.05) == (0.05, 0.02)


def _drive(lot, sigmas: float, shift: float, covariance, near: float = 0.0) -> list:
    """Spot 14 of the paper lot, the ego parking there; from step 5 on the estimate drifts ``shift`` m east of where
    the ego is (it follows its controls exactly). Returns the decisions."""
    s = unhurried()
    planner = EgoPlanner(lot, replace(s, decision=replace(s.decision, evasive=False, replan_pose_sigmas=sigmas,
                                                                    replan_pose_near=near),
                                      collision=replace(s.collision, reactive_steps=0)))
    ego, out = np.array([21.5, 25.0, -math.pi / 2]), []
    for k in range(12):
        estimate = ego + (np.array([shift, 0.0, 0.0]) if k >= 5 else 0.0)
        obs = replace(make_obs(lot, estimate, vacant=[14], step=k), ego_covariance=covariance)
        d = planner.decide(obs)
        out.append(d)
        assert len(d.poses) > 1
        ego = ego + (d.poses[1] - d.poses[0])  # the controls, driven exactly from the true pose
    return out


def test_a_small_drift_keeps_the_plan_only_with_the_switch(paper_lot):
    paper = _drive(paper_lot, 0.0, 0.10, COV)
    assert paper[0].reason == "new parking plan" and paper[5].replanned  # dropped when the estimate jumped
    kept = _drive(paper_lot, 2.0, 0.10, COV)
    assert all(d.reason == "executing" and not d.replanned for d in kept[1:])
    assert all(d.spot_id == 14 for d in kept)
    assert np.allclose(kept[5].poses[0][:2], kept[4].poses[1][:2] + [0.10, 0.0], atol=1e-9)  # moved onto it


def test_exact_sensing_and_a_large_drift_search_again(paper_lot):
    assert _drive(paper_lot, 2.0, 0.10, None)[5].replanned  # no covariance: the paper's re-check
    assert _drive(paper_lot, 2.0, 0.50, COV)[5].replanned  # 0.5 m > 2 x 0.15 m


def test_near_the_spot_the_papers_recheck_aims_again(paper_lot):
    """``decision.replan_pose_near``: with more path left than it the plan is moved (kept), with less it is searched
    again as the paper does."""
    from avp_motion.reanchor import remaining_length

    first = _drive(paper_lot, 2.0, 0.10, COV)[0]
    left = remaining_length(first.controls[5:], 0.1)
    assert not _drive(paper_lot, 2.0, 0.10, COV, near=left - 1.0)[5].replanned
    assert _drive(paper_lot, 2.0, 0.10, COV, near=left + 1.0)[5].replanned
