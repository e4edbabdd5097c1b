"""Spot selection (§V-D-1) as plugins: which candidate spots the ego plans to, in which order, and whether the
first one with a safe plan is taken or every candidate is priced and the lowest c_park wins.

The paper's rule (§V-D-1), over the candidates I_can,0 (observed vacant spots with belief <= δ): a plan is searched
"for each of the candidate spot", and "in the case of multiple feasible plans, the ego agent would choose the path
with the lowest cost c_park". The "Implicit" baseline of Table I (§VI-B-3) instead "would prioritize spots with
the highest intention probability that it can find a safe plan to". Both are built in:

* ``c_park`` (§V-D-1): every candidate is searched (branch and bound on the lower bound of c_park); the lowest
  c_park wins.
* ``ego_intention`` (§VI-B-3): candidates in the step's spot priority (the ego's own intention), the first with
  a safe plan wins; candidates the priority does not list come after, nearest first.
* ``auto`` (default): ``ego_intention`` on steps that carry a spot priority (methods with ``ego_intent``), else
  ``c_park``.

A plugin is a class ``Selector(lot)`` with ``select(candidates, context) -> Selection`` registered in the
entry-point group ``avp.spot_selectors`` and chosen with the planner parameter ``decision.spot_selector``
(docs/custom_predictor.md, "Your own spot selection"). Selection only orders and filters the candidates: the
planner still searches, prices and checks every plan against the predictions.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from avp_world import plugins
from avp_world.lot import LotMap
from avp_world.types import Observation

#: Python entry-point group of spot-selector plugins: ``name = "package.module:Class"``
ENTRY_POINT_GROUP = "avp.spot_selectors"
BUILTIN_SELECTORS = {
    "auto": "avp_planner.core.spot_selection:AutoSelector",
    "c_park": "avp_planner.core.spot_selection:LowestCostSelector",
    "ego_intention": "avp_planner.core.spot_selection:EgoIntentionSelector",
}


@dataclass(frozen=True)
class SelectionContext:
    """What a selector may look at on one decision step (the ego's own view; never ground truth)."""

    obs: Observation  # this step's observation
    beliefs: np.ndarray  # b_t,i per lot spot row (§V-B)
    ego: np.ndarray  # (3,) ego pose
    spot_priority: Sequence[int] | None  # spot ids, most wanted first (the ego's intention), or None


@dataclass(frozen=True)
class Selection:
    """``rows``: candidate spot rows (into the lot's spot arrays) to plan to, in the order to try; rows left out
    are not planned to. ``first_feasible``: take the first with a safe plan (True) or price all and take the
    lowest c_park (False; the order is then the planner's, by lower bound)."""

    rows: np.ndarray
    first_feasible: bool


def priority_order(lot: LotMap, candidates: np.ndarray, priority: Sequence[int], ego: np.ndarray) -> np.ndarray:
    """Candidate rows in the order of ``priority`` (spot ids); the rest after them, nearest first."""
    rank: dict[int, int] = {}
    for sid in priority:
        if lot.has_spot(int(sid)):
            rank.setdefault(lot.spot_index(int(sid)), len(rank))
    listed = sorted((int(i) for i in candidates if int(i) in rank), key=lambda i: rank[i])
    rest = [int(i) for i in candidates if int(i) not in rank]
    dist = {i: math.hypot(*(lot.spot_poses[i, :2] - ego[:2])) for i in rest}
    rest.sort(key=lambda i: (dist[i], i))
    return np.asarray(listed + rest, dtype=np.int64)


class LowestCostSelector:
    """§V-D-1: every candidate, lowest c_park."""

    name = "c_park"

    def __init__(self, lot: LotMap):
        self.lot = lot

    def select(self, candidates: np.ndarray, context: SelectionContext) -> Selection:
        return Selection(candidates, False)


class EgoIntentionSelector(LowestCostSelector):
    """§VI-B-3 (Implicit): the ego's intention order, first safe plan."""

    name = "ego_intention"

    def select(self, candidates: np.ndarray, context: SelectionContext) -> Selection:
        priority = () if context.spot_priority is None else context.spot_priority
        return Selection(priority_order(self.lot, candidates, priority, context.ego), True)


class AutoSelector(EgoIntentionSelector):
    """``ego_intention`` when the step carries a spot priority, else ``c_park``."""

    name = "auto"

    def select(self, candidates: np.ndarray, context: SelectionContext) -> Selection:
        if context.spot_priority is None:
            return Selection(candidates, False)
        return super().select(candidates, context)


def available_spot_selectors() -> dict[str, str]:
    """Every spot selector this installation can make: the built-ins, then the plugins."""
    return plugins.available(ENTRY_POINT_GROUP, BUILTIN_SELECTORS)


def spot_selector_class(name: str) -> type:
    """The class of spot selector ``name`` (built-in or ``avp.spot_selectors`` plugin); ValueError lists the names
    (the planner node checks its ``decision.spot_selector`` with it at start-up)."""
    return plugins.load_class(ENTRY_POINT_GROUP, BUILTIN_SELECTORS, name, "spot selector", "docs/custom_predictor.md")


def make_spot_selector(name: str, lot: LotMap):
    """The spot selector called ``name`` for ``lot``; ValueError lists the names."""
    selector = spot_selector_class(name)(lot)
    if not callable(getattr(selector, "select", None)):
        raise ValueError(f"spot selector {name!r}: {available_spot_selectors()[name]!r} made an object without a "
                         "select(candidates, context)")
    return selector
