"""avp_episode.ego_pool: K egos' pipelines in worker processes give the same commands and decisions, step for step,
as the same pipelines run one after the other in this process (deterministic pipelines, one seed of the paper lot)."""

from __future__ import annotations

import pytest

from avp_episode.ego import MethodEgo
from avp_episode.ego_pool import EgoPool
from avp_episode.fleet import ORACLE_HORIZON
from avp_episode.oracle import OracleEgo, ground_truth
from avp_episode.run_config import RunConfig, run_profile, sim_values
from avp_sim.core.factory import make_world

STEPS = 90


def _episode(paper_lot, methods, pool_workers: int) -> list[dict[int, tuple]]:
    """STEPS lot steps of seed 5 with one ego per method: per step, ego -> (command, decision's mode and spot)."""
    cfg = RunConfig(t_final=60.0, sim_overrides={"egos.entry_interval": 1.5})
    profiles = [run_profile(m, cfg) for m in methods]
    world = make_world(paper_lot, dict(sim_values(cfg), **{"egos.count": len(methods)}), 5, True)

    def make_input(i):
        return world.observe(i), ground_truth(world, ORACLE_HORIZON) if profiles[i].ground_truth else None

    pool = EgoPool(paper_lot, profiles, workers=pool_workers) if pool_workers else None
    egos = [] if pool else [(OracleEgo if p.ground_truth else MethodEgo)(paper_lot, p) for p in profiles]
    log = []
    try:
        while not world.done and world.step_index < STEPS:
            ids = [i for i in range(len(methods)) if world.egos.driving[i]]
            if pool is not None:
                steps = pool.step(ids, make_input)
            else:
                steps = {}
                for i in ids:
                    obs, truth = make_input(i)
                    if truth is not None:
                        egos[i].tell(truth)
                    steps[i] = egos[i].step(obs)
            log.append({i: (s.command, s.decision.mode if s.decision else None,
                            s.decision.spot_id if s.decision else None) for i, s in steps.items()})
            world.step_all([steps[i].command if i in steps else (0.0, 0.0) for i in range(len(methods))])
    finally:
        if pool is not None:
            pool.close()
    return log


def test_the_pool_steps_each_ego_as_one_thread_does(paper_lot):
    methods = ["bezier", "oracle", "bezier"]  # worker 0 holds egos 0 and 2; the oracle is told the truth in its worker
    serial = _episode(paper_lot, methods, 0)
    pooled = _episode(paper_lot, methods, 2)
    assert len(serial) == STEPS and pooled == serial
    assert {i for s in serial for i in s} == {0, 1, 2}, "every ego should have driven within the steps compared"


def test_a_failing_worker_names_itself_and_bad_sizes_are_refused(paper_lot):
    with pytest.raises(ValueError, match="workers must be at least 1"):
        EgoPool(paper_lot, [run_profile("bezier", RunConfig())], workers=0)
    with EgoPool(paper_lot, [run_profile("bezier", RunConfig())], workers=1) as pool:
        with pytest.raises(RuntimeError, match="worker 0 failed"):
            pool.step([0], lambda i: ("not an observation", None))
