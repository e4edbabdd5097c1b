"""The optional ``scenario:`` block of a lot YAML, validated as the lot is loaded (:func:`avp_world.lot.lot_from_dict`);
what its keys mean and the defaults of a lot without one: :mod:`avp_world.lot_scenario`. The block is checked against
the lot's spot ids only, so this module needs no :class:`~avp_world.lot.LotMap` (and the lot module imports it).
"""

from __future__ import annotations

import math
from typing import Any, Protocol

SCENARIO_KEYS = ("ego_start", "contested_spot_ids", "fallback_spot_groups", "aisle_width")


class SpotIds(Protocol):
    """What the check needs of a lot: its name and whether a spot id is one of its spots."""

    name: str

    def has_spot(self, spot_id: int) -> bool: ...


def parse_scenario_block(raw: Any, lot: SpotIds, where: str) -> dict[str, Any]:
    """Validate a lot's ``scenario:`` block against the lot (its ``name`` and ``has_spot``); ValueError naming
    ``where`` and the field."""
    if not isinstance(raw, dict):
        raise ValueError(f"{where}: expected a mapping with keys {list(SCENARIO_KEYS)}")
    unknown = sorted(set(raw) - set(SCENARIO_KEYS))
    if unknown:
        raise ValueError(f"{where}.{unknown[0]}: unknown key (known: {list(SCENARIO_KEYS)})")
    out: dict[str, Any] = {}
    if "ego_start" in raw:
        v = raw["ego_start"]
        if not isinstance(v, list) or len(v) != 3 or not all(_finite(x) for x in v):
            raise ValueError(f"{where}.ego_start: expected [x, y, theta] (finite numbers), got {v!r}")
        out["ego_start"] = tuple(float(x) for x in v)
    if "contested_spot_ids" in raw:
        out["contested_spot_ids"] = _spot_ids(raw["contested_spot_ids"], lot, f"{where}.contested_spot_ids")
        if not out["contested_spot_ids"]:
            raise ValueError(f"{where}.contested_spot_ids: at least one spot")
    if "fallback_spot_groups" in raw:
        g = raw["fallback_spot_groups"]
        if not isinstance(g, list):
            raise ValueError(f"{where}.fallback_spot_groups: expected a list of lists of spot ids, got {g!r}")
        out["fallback_spot_groups"] = tuple(_spot_ids(x, lot, f"{where}.fallback_spot_groups[{i}]")
                                            for i, x in enumerate(g))
    if "aisle_width" in raw:
        w = raw["aisle_width"]
        if not _finite(w) or w <= 0:
            raise ValueError(f"{where}.aisle_width: expected a positive number, got {w!r}")
        out["aisle_width"] = float(w)
    return out


def _finite(v: Any) -> bool:
    return not isinstance(v, bool) and isinstance(v, int | float) and math.isfinite(v)


def _spot_ids(v: Any, lot: SpotIds, where: str) -> tuple[int, ...]:
    if not isinstance(v, list):
        raise ValueError(f"{where}: expected a list of spot ids, got {v!r}")
    ids: list[int] = []
    for i, s in enumerate(v):
        if isinstance(s, bool) or not isinstance(s, int) or not lot.has_spot(s):
            raise ValueError(f"{where}[{i}]: {s!r} is not a spot id of lot '{lot.name}'")
        if s in ids:
            raise ValueError(f"{where}[{i}]: spot {s} listed twice")
        ids.append(int(s))
    return tuple(ids)
