"""Seed finding (avp_experiment.seeds): on a pool, the same seeds as one after another, and the verdicts cached."""

import json

import pytest

from avp_episode.pool import make_pool
from avp_episode.run_config import RunConfig, sim_values
from avp_experiment import seeds as seeds_mod
from avp_scenario.scenario import ScenarioError
from avp_sim.core.factory import generate_scenario, load_lot_param


@pytest.fixture(scope="module")
def sim_p():
    return sim_values(RunConfig(t_final=60.0))


def _builds(sim_p, seed):
    """The oracle: the generator itself, seed by seed."""
    try:
        generate_scenario(load_lot_param(sim_p["lot_file"]), sim_p, seed, False)
    except ScenarioError:
        return False
    return True


def test_serial_seeds_skip_the_seeds_without_a_scenario(sim_p, tmp_path):
    cache = tmp_path / "seeds.json"
    got, bad = seeds_mod.valid_seeds(5, 50, sim_p, cache)
    truth = {s: _builds(sim_p, s) for s in range(50, 57)}
    assert not truth[53], "seed 53 builds no scenario on the paper lot (docs/experiment.md)"
    assert got == [s for s in range(50, 57) if truth[s]][:5] and bad == [53]
    assert json.loads(cache.read_text()) == {str(s): truth[s] for s in range(50, 56)}


def test_a_pool_finds_the_same_seeds_and_a_slow_generator_starts_one(sim_p, tmp_path, monkeypatch):
    serial = seeds_mod.valid_seeds(6, 49, sim_p)
    pool = make_pool(2)
    try:
        assert seeds_mod.valid_seeds(6, 49, sim_p, tmp_path / "a.json", pool=pool) == serial
    finally:
        pool.shutdown()
    started = []
    monkeypatch.setattr(seeds_mod, "SLOW_SEED", 0.0)  # every seed "slow": the rest go to a pool of its own
    real = make_pool
    monkeypatch.setattr("avp_episode.pool.make_pool", lambda n: started.append(n) or real(n))
    assert seeds_mod.valid_seeds(6, 49, sim_p, tmp_path / "b.json", workers=2) == serial
    assert started == [2]
    assert json.loads((tmp_path / "b.json").read_text()) == json.loads((tmp_path / "a.json").read_text())
    started.clear()
    assert seeds_mod.valid_seeds(6, 49, sim_p, tmp_path / "b.json", workers=2) == serial  # all cached: no pool
    assert started == []
