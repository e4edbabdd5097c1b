"""K egos' pipelines spread over worker processes, so that a lot of several egos uses every core in one episode.

:func:`avp_episode.fleet.run_fleet_inproc` steps the K pipelines one after the other on one thread; an experiment
uses the other cores by running several episodes at once (``--workers``). A single live-speed episode (the K = 8
step-time target of docs/benchmarks.md, "Several egos") has only one lot step at a time, so :class:`EgoPool` runs
the pipelines of one step side by side: ego ``i`` lives in worker ``i % workers`` for the whole episode (its
perception memory, its planner's state), the simulator stays in the calling process, and each step sends every
worker its egos' observations and takes back their :class:`~avp_episode.ego.EgoStep`. Nothing about an ego's
inputs changes, so with ``deterministic=True`` the commands equal those of the pipelines run in one thread
(tests/test_ego_pool.py).

The workers are started with ``spawn`` (torch and a forked parent do not mix) and each uses one torch thread.
"""

from __future__ import annotations

import multiprocessing as mp
import traceback
from collections.abc import Callable
from multiprocessing.connection import Connection

from avp_episode.ego import EgoStep
from avp_episode.profiles import MethodProfile
from avp_world.lot import LotMap
from avp_world.types import Observation

#: seconds a worker may take to build its pipelines (loading torch and the intent CNN) before the pool gives up
START_TIMEOUT_S = 300.0


def _serve(conn: Connection, lot: LotMap, assigned: dict[int, MethodProfile], kwargs: dict) -> None:
    """A worker's loop: build the assigned egos' pipelines, then answer ``{i: (obs, truth)}`` with ``{i: EgoStep}``
    until ``None`` comes. An error is sent back as ``("error", traceback)``."""
    try:
        import torch

        torch.set_num_threads(1)
        from avp_episode.ego import MethodEgo
        from avp_episode.oracle import OracleEgo

        egos = {i: (OracleEgo if p.ground_truth else MethodEgo)(lot, p, **kwargs) for i, p in assigned.items()}
        conn.send("ready")
        while (msg := conn.recv()) is not None:
            out = {}
            for i, (obs, truth) in msg.items():
                if truth is not None:
                    egos[i].tell(truth)
                out[i] = egos[i].step(obs)
            conn.send(out)
    except Exception:  # noqa: BLE001 - the pool raises it in the caller, with the worker's traceback
        conn.send(("error", traceback.format_exc()))
    finally:
        conn.close()


class EgoPool:
    """The pipelines of ``profiles`` (ego ``i`` has ``profiles[i]``) in ``workers`` processes.

    Args:
        lot: the lot map.
        profiles: one method profile per ego.
        workers: worker processes (at most one per ego).
        **ego_kwargs: :class:`~avp_episode.ego.MethodEgo`'s keyword arguments (``deterministic``,
            ``intent_weights``, ``intent_seed``, ``message_precision``).
    """

    def __init__(self, lot: LotMap, profiles: list[MethodProfile], workers: int = 2, **ego_kwargs) -> None:
        if workers < 1:
            raise ValueError(f"EgoPool: workers must be at least 1, not {workers}")
        self.k = len(profiles)
        self.workers = min(workers, self.k)
        self.home = [i % self.workers for i in range(self.k)]
        ctx = mp.get_context("spawn")
        self._conns: list[Connection] = []
        self._procs = []
        for w in range(self.workers):
            parent, child = ctx.Pipe()
            assigned = {i: profiles[i] for i in range(self.k) if self.home[i] == w}
            proc = ctx.Process(target=_serve, args=(child, lot, assigned, ego_kwargs), daemon=True,
                               name=f"avp-ego-pool-{w}")
            proc.start()
            child.close()
            self._conns.append(parent)
            self._procs.append(proc)
        for w, conn in enumerate(self._conns):
            if not conn.poll(START_TIMEOUT_S):
                self.close()
                raise RuntimeError(f"EgoPool: worker {w} did not start within {START_TIMEOUT_S:.0f} s")
            self._check(conn.recv(), w)

    def _check(self, reply, w: int):
        if isinstance(reply, tuple) and len(reply) == 2 and reply[0] == "error":
            self.close()
            raise RuntimeError(f"EgoPool: worker {w} failed:\n{reply[1]}")
        return reply

    def step(self, ids: list[int],
             make_input: Callable[[int], tuple[Observation, object | None]]) -> dict[int, EgoStep]:
        """One step of the egos ``ids``; the others are not stepped. ``make_input(i)`` gives ego ``i``'s
        (observation, the ground truth an oracle is told, or None). A worker's batch leaves as soon as its egos'
        inputs are made, so the first worker computes while the caller ray-casts for the next. Returns ego index ->
        its step."""
        order = sorted(ids, key=lambda i: (self.home[i], i))
        busy: list[int] = []
        batch: dict = {}
        for n, i in enumerate(order):
            batch[i] = make_input(i)
            if n + 1 == len(order) or self.home[order[n + 1]] != self.home[i]:
                self._conns[self.home[i]].send(batch)
                busy.append(self.home[i])
                batch = {}
        out: dict[int, EgoStep] = {}
        for w in busy:
            out.update(self._check(self._conns[w].recv(), w))
        return out

    def close(self) -> None:
        """Stop the workers (idempotent)."""
        for conn in self._conns:
            try:
                conn.send(None)
            except (OSError, ValueError):
                pass
        for proc in self._procs:
            proc.join(timeout=10)
            if proc.is_alive():
                proc.kill()
        for conn in self._conns:
            conn.close()
        self._conns, self._procs = [], []

    def __enter__(self) -> EgoPool:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
