"""``decision.spot_commitment``: a new search after a driven parking plan was dropped prices the spot that plan aimed
at lower by the bonus, so a near tie does not switch spots (§V-D-1 takes the lowest c_park afresh: the paper, 0)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from test_planner_decision import make_obs
from unhurried import unhurried

from avp_planner.core.decision import EgoPlanner

START = np.array([21.5, 25.0, -math.pi / 2])


def _planner(lot, commitment: float) -> EgoPlanner:
    s = unhurried()
    return EgoPlanner(lot, replace(s, decision=replace(s.decision, evasive=False, spot_commitment=commitment),
                                   collision=replace(s.collision, reactive_steps=0)))


def _second_choice(lot, commitment: float):
    """Spot 14 alone vacant: a plan to it. Next step spot 15 is vacant too (cheaper in c_park) and the ego is 0.5 m
    from its plan (the plan is dropped): the decision of that step."""
    planner = _planner(lot, commitment)
    first = planner.decide(make_obs(lot, START, vacant=[14]))
    assert first.mode == "park" and first.spot_id == 14
    moved = first.poses[1] + np.array([0.5, 0.0, 0.0])
    return planner.decide(replace(make_obs(lot, moved, vacant=[14, 15]), step=1))


def test_the_paper_switches_to_the_cheaper_spot(paper_lot):
    d = _second_choice(paper_lot, 0.0)
    assert d.replanned and d.spot_id == 15


def test_a_bonus_larger_than_the_gap_keeps_the_spot_and_a_smaller_one_does_not(paper_lot):
    """From the new pose spot 15 is about 11.6 cheaper than spot 14 (both vacant): a bonus of 20 keeps 14, and the
    decision reports 14's own c_park (dearer than 15's); a bonus of 1 switches as the paper does."""
    paper = _second_choice(paper_lot, 0.0)
    kept = _second_choice(paper_lot, 20.0)
    assert kept.replanned and kept.spot_id == 14 and kept.cost > paper.cost + 1.0
    assert _second_choice(paper_lot, 1.0).spot_id == 15
