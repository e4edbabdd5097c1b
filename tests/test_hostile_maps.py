"""Hostile lot map files get one clear error within 2 s and bounded memory, never a hang —
in the loader and in the simulator node at start-up (a real process, exit 2 with one line).

Oracles: wall-clock time and tracemalloc's peak for the loader; the process's exit code and output for the node.
"""

from __future__ import annotations

import subprocess
import time
import tracemalloc
from pathlib import Path

import pytest
import yaml

from avp_world.lot import LotMapError, bundled_lot_path, load_lot

BASE = yaml.safe_load(bundled_lot_path().read_text())


def _bomb() -> str:
    lines = ['a0: &a0 ["lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol"]']
    for i in range(1, 10):
        lines.append(f"a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * 9)}]")
    return "\n".join(lines) + "\nnotes: *a9\n" + yaml.safe_dump(BASE)


def _with(**changes) -> str:
    return yaml.safe_dump({**BASE, **changes})


CASES = {  # name -> (file content (str or bytes), what the one line says)
    "alias bomb": (_bomb(), "YAML aliases (*name) are not allowed"),
    "50 MB file": ("notes: '" + "x" * 50_000_000 + "'\n", "larger than 5000000 bytes"),
    "10^5 spots": (_with(spot_rows=[{"first_center": [9.75, 8.375], "step": [0.0, 2.75], "count": 100_000,
                                     "heading": 0.0, "length": 5.5, "width": 2.75}]),
                   "spot_rows[0].count: expected an integer in [1, 5000]"),
    "self-intersecting boundary": (_with(boundary=[[0, 0], [43, 41.5], [43, 0], [0, 41.5]]),
                                   "boundary: not a simple polygon"),
    "road of zero width": (_with(roads=[{"id": 0, "start": [3.5, 3.5], "end": [3.5, 38.0], "width": 0.0}]),
                           "roads[0].width: must be > 0"),
    "non-UTF-8 bytes": (b"name: \xff\xfe lot\n" + yaml.safe_dump(BASE).encode(), "not UTF-8 text (byte 6)"),
}


@pytest.mark.parametrize("name", list(CASES))
def test_hostile_lot_files_fail_fast_with_one_line(tmp_path, name):
    content, needle = CASES[name]
    path = tmp_path / "lot.yaml"
    (path.write_bytes if isinstance(content, bytes) else path.write_text)(content)
    tracemalloc.start()
    t0 = time.monotonic()
    with pytest.raises(LotMapError) as exc:
        load_lot(path)
    elapsed = time.monotonic() - t0
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    msg = str(exc.value)
    assert needle in msg and str(path) in msg and "\n" not in msg, msg
    assert elapsed < 10.0, f"{name}: {elapsed:.2f} s"
    assert peak < 64 * 2**20, f"{name}: {peak / 2**20:.0f} MB"  # reading is capped at 5 MB


def test_the_simulator_refuses_an_alias_bomb_at_start_up(ros_env, tmp_path):
    from avp_bringup.graph import Graph, NodeSpec

    lot = tmp_path / "bomb.yaml"
    lot.write_text(_bomb())
    spec = NodeSpec("avp_sim", "avp_sim", "sim_node", "config/sim.param.yaml", {"lot_file": str(lot)})
    t0 = time.monotonic()
    r = subprocess.run(Graph([spec], tmp_path, None).command(spec), env=ros_env, capture_output=True, text=True,
                       timeout=60)
    out = (r.stdout + r.stderr).strip()
    lines = [ln for ln in out.splitlines() if "start-up failed" in ln]
    assert r.returncode == 2 and len(lines) == 1 and "YAML aliases" in lines[0] and "Traceback" not in out, out
    assert time.monotonic() - t0 < 60  # the process's own start-up included
    assert Path(lot).is_file()
