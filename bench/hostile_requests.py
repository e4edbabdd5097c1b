"""The hostile ``reset_episode`` requests of docs/bad_input.md rows 30-32 and 50, built once, shared by
bench/bench_requests.py (how fast each is refused), bench/flood_publisher.py (``--bad-resets``: a stream of them
into a running episode) and the tests. Each entry: name -> (request fields, a text its refusal must contain).
"""

from __future__ import annotations

import math
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = ROOT / "src/avp_sim/config/scenarios/two_cars.yaml"


def hostile_requests() -> dict[str, tuple[dict, str]]:
    """Requests every simulator must refuse quickly, whatever lot it runs."""
    base = yaml.safe_load(SCENARIO.read_text())
    one = {k: base["dynamic_vehicles"][0][k] for k in ("target_spot", "maneuver")}
    many = yaml.safe_dump({**base, "dynamic_vehicles": [dict(one) for _ in range(10_000)]})  # ~500 KB
    flow = "vacant_spot_ids: [" + ",".join(["1"] * 499_000) + "]\n"  # just under 1 MB, 499 000 nodes
    keys = "".join(f"k{i}: {i}\n" for i in range(60_000))  # a 60 000-key mapping, under the 1 MB cap
    deep = "[" * 5_000 + "]" * 5_000
    texts = {
        "10 000 vehicles (500 KB)": (many, "more than 16384 YAML nodes"),
        "1 MB flow list": (flow, "more than 16384 YAML nodes"),
        "60 000-key mapping": (keys, "more than 16384 YAML nodes"),
        "5 000-deep list": (deep, "nested deeper than 8 levels"),
        "2 MB text": ("#" * 2_000_000, "larger than 1000000 bytes"),
        "alias": ("a: &x [1, 2]\nvacant_spot_ids: *x\n", "YAML aliases"),
        "NaN ego pose": (yaml.safe_dump({**base, "ego_start": [math.nan, 38.0, 0.0]}), "ego_start[0]"),
        "ego outside the lot": (yaml.safe_dump({**base, "ego_start": [-50.0, 0.0, 0.0]}), "ego's footprint"),
        "65 vehicles": (yaml.safe_dump({**base, "dynamic_vehicles": [dict(one) for _ in range(65)]}),
                        "65 vehicles, at most 64"),
        "unknown maneuver": (yaml.safe_dump({**base, "dynamic_vehicles": [{**one, "maneuver": "near/x/y"}]}),
                             "is not one of"),
    }
    out = {name: ({"scenario_yaml": text}, needle) for name, (text, needle) in texts.items()}
    refused = "not a file of the served scenario directories"
    for path in ("/dev/zero", "/etc/passwd", "../outside.yaml"):
        out[f"scenario_file {path}"] = ({"scenario_file": path}, refused)
    out["both fields"] = ({"scenario_file": "two_cars.yaml", "scenario_yaml": "{}"}, "give one of them")
    return out
