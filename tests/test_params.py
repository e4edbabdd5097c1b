"""Shipped parameter files validate against their specs; bad values give one line naming node and key."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from avp_common.params import ParameterError, load_yaml_params
from avp_perception.params import BELIEF_PARAMS, PREDICTION_PARAMS
from avp_planner.examples.minimal_planner import MINIMAL_PARAMS
from avp_planner.planner_node import PLANNER_PARAMS
from avp_planner.reservation_node import RESERVATION_PARAMS
from avp_planner.scripted_driver_node import DRIVER_PARAMS
from avp_planner.v2v_node import V2V_PARAMS
from avp_sim.params import SIM_PARAMS
from avp_viz.scene_node import SCENE_PARAMS

SRC = Path(__file__).resolve().parents[1] / "src"
FILES = [("avp_sim", SRC / "avp_sim/config/sim.param.yaml", SIM_PARAMS),
         ("avp_planner", SRC / "avp_planner/config/planner.param.yaml", PLANNER_PARAMS),
         ("scripted_driver", SRC / "avp_planner/config/scripted_driver.param.yaml", DRIVER_PARAMS),
         ("avp_belief", SRC / "avp_perception/config/belief.param.yaml", BELIEF_PARAMS),
         ("avp_prediction", SRC / "avp_perception/config/prediction.param.yaml", PREDICTION_PARAMS),
         ("minimal_planner", SRC / "avp_planner/config/minimal_planner.param.yaml", MINIMAL_PARAMS),
         ("avp_scene", SRC / "avp_viz/config/scene.param.yaml", SCENE_PARAMS),
         ("avp_reservation", SRC / "avp_planner/config/reservation.param.yaml", RESERVATION_PARAMS),
         ("avp_v2v", SRC / "avp_planner/config/v2v.param.yaml", V2V_PARAMS)]


@pytest.mark.parametrize("node,path,specs", FILES, ids=[f[0] for f in FILES])
def test_shipped_files_are_complete_and_valid(node, path, specs):
    values = load_yaml_params(path, node, specs)
    assert set(values) == {s.name for s in specs}
    stale = [s.name for s in specs if values[s.name] != pytest.approx(s.default)]
    assert stale == [], f"{path} is out of date with the settings (run tools/gen_params.py)"


def _mutated(tmp_path, path, key, value):
    data = yaml.safe_load(path.read_text())
    node = data["/**"]["ros__parameters"]
    *parents, leaf = key.split(".")
    for p in parents:
        node = node[p]
    if value is KeyError:
        del node[leaf]
    else:
        node[leaf] = value
    out = tmp_path / "p.yaml"
    out.write_text(yaml.safe_dump(data))
    return out


BAD = [
    ("avp_sim", "dt", -0.1, "below the minimum"),
    ("avp_sim", "sensor.n_ray", 3.5, "expected an integer"),
    ("avp_sim", "mode", "fast", "not one of"),
    ("avp_sim", "t_final", KeyError, "missing"),
    ("avp_sim", "reactive", "yes", "expected true/false"),
    ("avp_sim", "sensor.radius", float("nan"), "finite"),
    ("avp_planner", "search.max_iterations", "many", "expected an integer"),
    ("avp_planner", "decision.candidate_threshold", KeyError, "missing"),
    ("avp_belief", "bev.beta", 1.5, "above the maximum"),
    ("avp_belief", "belief_source", "oracle", "not one of"),
    ("avp_belief", "nawaz.alpha", 1.5, "above the maximum"),
    ("avp_planner", "use_ego_intention", "yes", "expected true/false"),
    ("avp_belief", "debug.bev", "sometimes", "not one of"),
    ("avp_prediction", "method", "kalman", "not one of"),
    ("avp_prediction", "hybrid_astar.max_iterations", 0, "below the minimum"),
    ("avp_prediction", "mu", KeyError, "missing"),
]


@pytest.mark.parametrize("node,key,value,needle", BAD, ids=[f"{b[0]}:{b[1]}" for b in BAD])
def test_bad_values_name_node_and_key(tmp_path, node, key, value, needle):
    path, specs = next((p, s) for n, p, s in FILES if n == node)
    bad = _mutated(tmp_path, path, key, value)
    with pytest.raises(ParameterError) as exc:
        load_yaml_params(bad, node, specs)
    msg = str(exc.value)
    assert f"'{key}'" in msg and needle in msg and str(bad) in msg and "\n" not in msg


def test_unknown_key_is_an_error(tmp_path):
    bad = _mutated(tmp_path, FILES[0][1], "sensor.radiuss", 3.0)
    with pytest.raises(ParameterError, match="'sensor.radiuss': unknown key"):
        load_yaml_params(bad, "avp_sim", SIM_PARAMS)
