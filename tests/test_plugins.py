"""Plugins the ROS way in Python: a predictor and a spot selector from a package outside src/,
found through the ``avp.predictors`` and ``avp.spot_selectors`` entry-point groups, run episodes through
``avp experiment --methods <their profiles>``; an experiment transport (``avp.experiment_transports``: the
DDS one is avp_bringup's) runs them through ``avp experiment --transport <its name>``.

The toy package is built and installed by pip (``--target``, so the workspace's environment is left as it was);
the experiment's worker process finds it on PYTHONPATH, like any installed package.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

TOY_MODULE = '''
"""A toy predictor: every other vehicle keeps its pose (and each call is counted in $TOY_PREDICTOR_LOG)."""
import os

from avp_predictors.prediction import StaticPredictor


class ToyPredictor(StaticPredictor):
    name = "toy"

    def predict(self, obs, intentions=(), horizon=None):
        with open(os.environ["TOY_PREDICTOR_LOG"], "a") as f:
            f.write(f"{obs.step}\\n")
        return super().predict(obs, intentions, horizon)


class FarthestFirst:
    """A toy spot selector: the candidate farthest from the ego first, the first safe plan wins (each call's
    order of spot ids is written to $TOY_SELECTOR_LOG)."""

    name = "farthest"

    def __init__(self, lot):
        self.lot = lot

    def select(self, candidates, context):
        import numpy as np

        from avp_planner.core.spot_selection import Selection

        d = np.hypot(*(self.lot.spot_poses[candidates, :2] - context.ego[:2]).T)
        rows = np.asarray(candidates)[np.argsort(-d, kind="stable")]
        with open(os.environ["TOY_SELECTOR_LOG"], "a") as f:
            f.write(" ".join(str(int(self.lot.spot_ids[r])) for r in rows) + "\\n")
        return Selection(rows, True)


def run_toy_transport(keys, cfg, on_record, log_dir, timeout=600.0):
    """A toy experiment transport: the episodes in this process, each key written to $TOY_TRANSPORT_LOG."""
    from avp_episode.episodes import _init_worker, _worker_episode

    _init_worker(cfg)
    for key in keys:
        with open(os.environ["TOY_TRANSPORT_LOG"], "a") as f:
            f.write(" ".join(map(str, key)) + "\\n")
        record = _worker_episode(key)
        record["transport"] = "toy"
        on_record(record)
'''

TOY_SETUP = '''
from setuptools import setup

setup(name="toy-predictor", version="0.1.0", py_modules=["toy_predictor"],
      entry_points={"avp.predictors": ["toy = toy_predictor:ToyPredictor"],
                    "avp.spot_selectors": ["farthest = toy_predictor:FarthestFirst"],
                    "avp.experiment_transports": ["toy = toy_predictor:run_toy_transport"]})
'''

TOY_PROFILE = """
name: toy
label: Toy (a plugin)
group: Plugins
available: true
perception:
  beliefs: intent
  predictor: toy
  ego_intent: false
planner:
  use_beliefs: true
  use_predictions: true
"""

SELECTOR_PROFILE = """
name: farthest
label: Farthest spot first (a plugin)
group: Plugins
available: true
perception:
  beliefs: intent
  predictor: bezier
  ego_intent: false
planner:
  use_beliefs: true
  use_predictions: true
  decision.spot_selector: farthest
"""


@pytest.fixture(scope="module")
def toy(tmp_path_factory) -> dict:
    root = tmp_path_factory.mktemp("toy")
    (root / "pkg").mkdir()
    (root / "pkg" / "toy_predictor.py").write_text(TOY_MODULE)
    (root / "pkg" / "setup.py").write_text(TOY_SETUP)
    (root / "profiles").mkdir()
    (root / "profiles" / "toy.yaml").write_text(TOY_PROFILE)
    (root / "profiles" / "farthest.yaml").write_text(SELECTOR_PROFILE)
    r = subprocess.run([sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--no-build-isolation",
                        "--no-index", "--target", str(root / "site"), str(root / "pkg")],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(root / "site"), env.get("PYTHONPATH", "")])
    env["TOY_PREDICTOR_LOG"] = str(root / "calls.log")
    env["TOY_SELECTOR_LOG"] = str(root / "selector.log")
    env["TOY_TRANSPORT_LOG"] = str(root / "transport.log")
    return {"root": root, "env": env}


def test_the_entry_point_makes_the_predictor_and_unknown_names_list_the_plugins(toy):
    code = ("from avp_predictors.prediction import available_predictors, make_predictor\n"
            "from avp_world.lot import load_bundled_lot\n"
            "print(type(make_predictor('toy', load_bundled_lot())).__name__)\n"
            "print(sorted(available_predictors()))\n"
            "try:\n    make_predictor('nope')\nexcept ValueError as e:\n    print(e)\n")
    r = subprocess.run([sys.executable, "-c", code], env=toy["env"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    lines = r.stdout.splitlines()
    assert lines[0] == "ToyPredictor" and "'toy'" in lines[1] and "'bezier'" in lines[1]
    assert "unknown predictor 'nope'" in lines[2] and "'toy'" in lines[2] and "avp.predictors" in lines[2]
    # without the package on the path the name is unknown: the plugin, not a copy in src/, made it
    r = subprocess.run([sys.executable, "-c", "from avp_predictors.prediction import available_predictors\n"
                        "print('toy' in available_predictors())"], capture_output=True, text=True)
    assert r.stdout.strip() == "False"


@pytest.mark.slow
def test_avp_experiment_runs_an_episode_with_the_plugin(toy, tmp_path):
    out = tmp_path / "out"
    profile = toy["root"] / "profiles" / "toy.yaml"
    r = subprocess.run([sys.executable, "-m", "avp_bringup.cli", "experiment", "--methods", f"bezier,{profile}",
                        "--scenarios", "1", "--mode", "non-reactive", "--workers", "1", "--t-final", "20",
                        "--no-progress", "--out", str(out)], env=toy["env"], capture_output=True, text=True,
                       timeout=600)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    records = [json.loads(line) for line in (out / "episodes.jsonl").read_text().splitlines()]
    assert sorted(x["method"] for x in records) == ["bezier", "toy"]
    calls = (toy["root"] / "calls.log").read_text().split()
    toy_rec = next(x for x in records if x["method"] == "toy")
    assert len(calls) >= toy_rec["steps"] > 0  # the plugin predicted on every step of its episode
    assert "Toy (a plugin)" in (out / "summary.md").read_text()


@pytest.mark.slow
def test_a_spot_selector_plugin_chooses_the_spot(toy, tmp_path):
    """The selector plugin orders the candidates of every planning step, and the ego parks where the first of
    them with a safe plan lies (the farthest); an unknown selector is one error naming the parameter."""
    out = tmp_path / "out"
    profile = toy["root"] / "profiles" / "farthest.yaml"
    # seed 5: two candidate spots are in view when the ego first can park (on most seeds of the paper lot only one
    # is, and every rule parks in it)
    r = subprocess.run([sys.executable, "-m", "avp_bringup.cli", "experiment", "--methods", f"bezier,{profile}",
                        "--scenarios", "1", "--seed-base", "5", "--mode", "non-reactive", "--workers", "1",
                        "--t-final", "40", "--no-progress", "--out", str(out)], env=toy["env"], capture_output=True,
                       text=True, timeout=600)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    records = {x["method"]: x for x in map(json.loads, (out / "episodes.jsonl").read_text().splitlines())}
    assert records["bezier"]["seed"] == records["farthest"]["seed"] == 5
    orders = [line.split() for line in (toy["root"] / "selector.log").read_text().splitlines() if line.strip()]
    assert orders, "the plugin was never asked"
    far, near = records["farthest"]["parked_spot_id"], records["bezier"]["parked_spot_id"]
    assert records["farthest"]["success"] and records["bezier"]["success"]
    assert far != near  # the lowest c_park (the paper's rule) and the farthest-first plugin choose apart
    # when the plugin's choice was made, it ranked that spot before the one c_park took
    assert any(far in o and near in o and o.index(far) < o.index(near) for o in
               ([int(s) for s in line] for line in orders))
    code = ("from avp_planner.core.decision import EgoPlanner\n"
            "from avp_motion.settings import PlannerSettings, DecisionSettings\n"
            "from avp_world.lot import load_bundled_lot\n"
            "s = PlannerSettings(decision=DecisionSettings(spot_selector='nope'))\n"
            "try:\n    EgoPlanner(load_bundled_lot(), s)\n"
            "except ValueError as e:\n    print(e)\n")
    r = subprocess.run([sys.executable, "-c", code], env=toy["env"], capture_output=True, text=True)
    assert "unknown spot selector 'nope'" in r.stdout and "'farthest'" in r.stdout and "'c_park'" in r.stdout


def test_an_experiment_transport_plugin_runs_the_episodes(toy, tmp_path):
    """``--transport`` takes the transports installed as plugins: avp_bringup's ``ros`` and the toy one here, which
    alone runs the episodes of this command (its log names each key; its records say so)."""
    code = "from avp_experiment.transports import transport_names\nprint(transport_names())"
    r = subprocess.run([sys.executable, "-c", code], env=toy["env"], capture_output=True, text=True)
    assert r.returncode == 0 and r.stdout.strip() == "['inproc', 'ros', 'toy']", r.stdout + r.stderr
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert r.stdout.strip() == "['inproc', 'ros']"
    out = tmp_path / "out"
    r = subprocess.run([sys.executable, "-m", "avp_bringup.cli", "experiment", "--methods", "bezier",
                        "--transport", "toy", "--scenarios", "2", "--mode", "non-reactive", "--t-final", "10",
                        "--no-progress", "--out", str(out)], env=toy["env"], capture_output=True, text=True,
                       timeout=600)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    records = [json.loads(line) for line in (out / "episodes.jsonl").read_text().splitlines()]
    assert len(records) == 2 and {x["transport"] for x in records} == {"toy"}
    logged = (toy["root"] / "transport.log").read_text().splitlines()
    assert sorted(logged) == sorted(f"bezier {x['seed']} non_reactive" for x in records)
    r = subprocess.run([sys.executable, "-m", "avp_bringup.cli", "experiment", "--transport", "nope", "--out",
                        str(tmp_path / "x")], env=toy["env"], capture_output=True, text=True)
    assert r.returncode == 2 and "invalid choice: 'nope'" in r.stderr and "'toy'" in r.stderr
