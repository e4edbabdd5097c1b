"""Which seeds build a scenario: the first ``n`` seeds >= ``seed_base`` that the scenario generator accepts (§VI-A).

A seed is tried by generating its scenario. On the paper's lot that takes ~40 ms, on the busy DLP lot seconds (the
traffic's Reeds-Shepp plans), so a run of a hundred busy scenarios spent minutes finding its seeds on one core
while the others waited. With a process pool the seeds are tried on every worker at once, a batch at a time; the
answer is the same seeds in the same order as one after another (a seed's verdict depends on the seed alone), and
``cache`` (a JSON file {seed: valid}, ``OUT/seeds.json``) keeps the verdicts for a re-run or the next cell.
"""

from __future__ import annotations

import functools
import json
import time
from concurrent.futures import Executor
from pathlib import Path

SLOW_SEED = 0.5  # s: a seed slower than this to generate, and valid_seeds tries the rest on a pool of its own


@functools.lru_cache(maxsize=4)
def _lot(lot_file: str):
    from avp_sim.core.factory import load_lot_param

    return load_lot_param(lot_file)


def seed_builds(sim_p: dict, seed: int) -> bool:
    """Whether the generator of ``sim_p`` builds a scenario for ``seed`` (runs in a pool worker)."""
    from avp_scenario.scenario import ScenarioError
    from avp_sim.core.factory import generate_scenario

    try:
        generate_scenario(_lot(sim_p["lot_file"]), sim_p, seed, False)
    except ScenarioError:
        return False
    return True


def valid_seeds(n: int, seed_base: int, sim_p: dict, cache: Path | None = None,
                pool: Executor | None = None, workers: int = 1) -> tuple[list[int], list[int]]:
    """The first ``n`` seeds >= ``seed_base`` for which the §VI-A generator builds a scenario, and the seeds
    skipped on the way (no collision-free plans for the dynamic vehicles, e.g. 53, 162, 253, 448 and 476 below 500).
    ``cache`` (a JSON file {seed: valid}) saves the generation of a re-run. ``pool`` tries the unknown seeds in
    parallel, as many at a time as are still needed; without one, ``workers`` > 1 starts a pool of its own for the
    rest once a seed has taken longer than :data:`SLOW_SEED` (the busy lot's seconds, not the paper lot's 40 ms)."""
    from avp_episode.pool import make_pool

    known: dict[str, bool] = json.loads(cache.read_text()) if cache is not None and cache.is_file() else {}

    def walk() -> tuple[list[int], list[int], int | None]:
        """(valid, skipped, the first unknown seed) from ``seed_base`` until ``n`` are valid or one is unknown."""
        seeds, bad = [], []
        s = seed_base
        while len(seeds) < n:
            if str(s) not in known:
                return seeds, bad, s
            (seeds if known[str(s)] else bad).append(s)
            s += 1
        return seeds, bad, None

    own: Executor | None = None
    try:
        seeds, bad, first = walk()
        while first is not None:
            ex = pool or own
            batch = [s for s in range(first, first + (n - len(seeds) if ex is not None else 1)) if str(s) not in known]
            t0 = time.perf_counter()
            verdicts = list(ex.map(seed_builds, [sim_p] * len(batch), batch)) if ex is not None and len(batch) > 1 \
                else [seed_builds(sim_p, s) for s in batch]
            if ex is None and workers > 1 and time.perf_counter() - t0 > SLOW_SEED:
                own = make_pool(workers)
            known.update({str(s): ok for s, ok in zip(batch, verdicts, strict=True)})
            seeds, bad, first = walk()
    finally:
        if own is not None:
            own.shutdown(wait=True, cancel_futures=True)
        if cache is not None:
            cache.write_text(json.dumps(known, sort_keys=True))
    return seeds, bad
