"""Gridlock: a cycle in the waits-for graph between egos and agents, held for a while (docs/metrics.md).

Each step has edges "A waits for B":
* an ego that stands or waits (its decision trace's mode is idle or a wait) waits for the agent its trace names as
  blocking it (:mod:`avp_motion.trace`; another ego is named by its observed id, ``EGO_ID_BASE + j``);
* an agent that brakes for an ego (§III-B's rule, :attr:`avp_sim.core.world.World.braking_for`) waits for that ego.

A step is gridlocked when those edges hold a cycle (ego 0 waits for car 7, car 7 brakes for ego 0; or two egos each
waiting for the other); an episode is gridlocked when one cycle of the same members lasts at least ``min_s`` seconds
(5 s by default). Nodes are ``("ego", i)`` and ``("agent", id)``.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping

Node = tuple[str, int]


def find_cycle(edges: Mapping[Node, Iterable[Node]]) -> frozenset[Node] | None:
    """The members of one cycle of the directed graph ``edges`` (the first found in sorted order), or None."""
    done: set[Node] = set()
    for root in sorted(edges):
        if root in done:
            continue
        stack: list[tuple[Node, list[Node]]] = [(root, sorted(edges.get(root, ())))]
        on_path = [root]
        seen_here = {root}
        while stack:
            node, todo = stack[-1]
            if not todo:
                stack.pop()
                on_path.pop()
                done.add(node)
                continue
            nxt = todo.pop(0)
            if nxt in seen_here and nxt in on_path:
                return frozenset(on_path[on_path.index(nxt):])
            if nxt in done or nxt in seen_here:
                continue
            seen_here.add(nxt)
            on_path.append(nxt)
            stack.append((nxt, sorted(edges.get(nxt, ()))))
    return None


class GridlockMeter:
    """Feed each step's waits-for edges (:meth:`add`); :meth:`summary` says whether a cycle lasted ``min_s``."""

    def __init__(self, dt: float, min_s: float = 5.0):
        self.dt, self.min_steps = float(dt), max(1, int(round(min_s / dt)))
        self._cycle: frozenset[Node] | None = None
        self._since = 0
        self.spells: list[dict] = []  # each cycle that lasted min_s: members, start and length

    def add(self, step: int, edges: Mapping[Node, Iterable[Node]]) -> frozenset[Node] | None:
        cycle = find_cycle(edges)
        if cycle != self._cycle:
            self._close(step)
            self._cycle, self._since = cycle, step
        return cycle

    def _close(self, step: int) -> None:
        if self._cycle is not None and step - self._since >= self.min_steps:
            self.spells.append({"members": sorted(f"{k}:{i}" for k, i in self._cycle),
                                "start_s": round(self._since * self.dt, 3),
                                "seconds": round((step - self._since) * self.dt, 3)})

    def summary(self, end_step: int) -> dict:
        self._close(end_step + 1)
        self._cycle = None
        return {"gridlock": bool(self.spells), "gridlock_s": round(sum(s["seconds"] for s in self.spells), 3),
                "gridlock_spells": list(self.spells)}
