"""The headline results table (avp_experiment.headline, `make results`): the README's table is the one the committed
records give, every cell of the suite is a valid `avp experiment` command, and a suite runs and tabulates."""

from __future__ import annotations

import gzip
import json
import subprocess
import sys
from pathlib import Path

import pytest

from avp_episode.metrics import wilson
from avp_experiment.headline import (
    BEGIN,
    END,
    cell_argv,
    load_suite,
    markers,
    readme_groups,
    render,
    render_narrow,
    replace_block,
    suite_table,
)

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def committed() -> dict:
    return suite_table(load_suite("headline"), root=ROOT)


def test_the_readme_table_is_the_one_the_committed_records_give(committed):
    readme = (ROOT / "README.md").read_text()
    assert readme_groups(committed) == ["main", "sensing"]
    for group in readme_groups(committed):
        begin, end = markers(group)
        block = readme.split(begin)[1].split(end)[0]
        assert block.strip() == render_narrow(committed, group).strip(), \
            f"README.md's {group} table is stale: run `make results-table`"
    page = (ROOT / "docs/results/README.md").read_text()
    block = page.split(BEGIN)[1].split(END)[0]
    assert block.strip() == render(committed).strip(), "docs/results/README.md's table is stale: `make results-table`"
    stored = json.loads((ROOT / "docs/results/headline.json").read_text())
    assert stored == json.loads(json.dumps(committed)), "docs/results/headline.json is stale: `make results-table`"


def test_the_readme_stays_a_front_page(committed):
    """README.md: under 1 200 words before its Documentation links, no table row over 130 characters, and every
    row of its results table a term of its glossary (a method named there has a row, a row has a definition)."""
    readme = (ROOT / "README.md").read_text()
    front = readme.split("## Documentation")[0]
    assert len(front.split()) < 1200, len(front.split())
    long = [line for line in readme.splitlines() if line.startswith("|") and len(line) > 130]
    assert not long, long
    glossary = front.split("Glossary:")[1].split("\n## ")[0].lower()
    for row in committed["rows"]:
        name = row["short"].split(",")[0].split("(")[0].strip().lower()
        if name.startswith("bézier"):
            name = row["short"].split(",")[-1].replace("profile", "").strip().lower()
        assert name in glossary, f"the results row {row['short']!r} is not in the README's glossary"
    for col in committed["columns"]:
        term = col["short"].split(":")[0].strip().lower()
        assert term in glossary, f"the column {col['short']!r} is not in the README's glossary"


def test_a_cell_agrees_with_its_records_read_independently(committed):
    # the shipped default on the busy lot: read the committed file with gzip + json alone, count, and compute Wilson
    path = ROOT / "docs/results/busy_dlp/default_reaction_assumed/episodes.jsonl.gz"
    with gzip.open(path, "rt") as f:
        recs = [json.loads(line) for line in f]
    k, n = sum(r["status"] == "success" for r in recs), len(recs)
    cell = committed["cells"]["busy_dlp"]["bezier"]
    assert (cell["success"]["k"], cell["success"]["n"]) == (k, n) == (156, 200)
    lo, hi = wilson(k, n)
    assert cell["success"]["ci95"] == [round(100 * lo, 1), round(100 * hi, 1)]
    stolen = sum(r["spot_stolen"] for r in recs)
    assert cell["spot_stolen"]["k"] == stolen
    assert cell["interrupted_steps"]["mean"] == round(sum(r["interrupted_steps"] for r in recs) / n, 1)


@pytest.mark.parametrize("name", ["headline", "fleet", "sensing"])
def test_every_cell_of_the_suite_is_a_valid_experiment_command(name):
    from avp_episode.profiles import load_profile
    from avp_experiment.headline import suite_method
    from avp_experiment.runner import _cell_args

    suite = load_suite(name)
    for col in suite["columns"]:
        for row in suite["rows"]:
            for quick in (False, True):
                args = _cell_args(cell_argv(col, row, quick))
                assert args.methods == ",".join(suite_method(m) for m in row["methods"].split(","))
                for m in args.methods.split(","):  # a profile file of the suite's methods/ is there and loads
                    assert not m.endswith(".yaml") or load_profile(m).name == Path(m).stem
                full = int(col["args"][col["args"].index("--scenarios") + 1])
                assert args.scenarios == (col["quick"] if quick else full)


def test_the_fleet_grid_gives_the_last_ego_the_time_the_second_has_in_a_pair():
    """Every fleet column: K egos 5 s apart (egos.entry_interval), t_f = 60 + 5 (K - 2) for K >= 2, so the K-th ego
    has the 55 s the second has in a 60 s episode of two (config/suites/fleet.yaml)."""
    from avp_experiment.runner import _cell_args

    suite = load_suite("fleet")
    sizes = set()
    for col in suite["columns"]:
        args = _cell_args(cell_argv(col, suite["rows"][0], False))
        sizes.add(args.egos)
        assert args.t_final == 60 + 5 * max(args.egos - 2, 0), col["id"]
        assert args.mode == "reactive" and args.scenarios == 100
    assert sizes == {1, 2, 4, 8}


@pytest.mark.parametrize("name", ["headline", "fleet", "sensing"])
def test_every_cell_of_a_shipped_suite_has_a_method_to_run(name):
    """A cell whose method the runner would skip (say `reserve` with one ego) stops the suite: none may ship."""
    from avp_experiment.headline import runs_in
    from avp_experiment.runner import _cell_args, resolve_methods

    suite = load_suite(name)
    for col in suite["columns"]:
        for row in suite["rows"]:
            if runs_in(row, col):
                args = _cell_args(cell_argv(col, row, False))
                run, skipped = resolve_methods(args.methods, egos=args.egos)
                assert run and not skipped, (col["id"], row["id"], skipped)


def _run_tiny_suite(tmp_path: Path, text: str, run_one) -> Path:
    """``run_suite`` on the suite file ``text`` (into tmp_path/out, every column and row) with ``run_one`` for the
    runner and the runner's method check; returns the OUT folder."""
    import argparse

    from avp_experiment.headline import run_suite
    from avp_experiment.runner import _cell_args, resolve_methods

    suite = tmp_path / "tiny.yaml"
    suite.write_text(text)
    args = argparse.Namespace(suite=str(suite), out=str(tmp_path / "out"), quick=False, columns="", rows="")
    run_suite(args, run_one, _cell_args, resolve_methods)
    return tmp_path / "out"


def test_a_suite_with_a_cell_that_cannot_run_is_refused_before_any_cell_runs(tmp_path):
    ran = []
    with pytest.raises(ValueError, match=r"k1 / reserve: reserve: coordinates several egos"):
        _run_tiny_suite(tmp_path, """
name: bad
rows:
  - {id: blind, label: blind, methods: blind}
  - {id: reserve, label: reserve, methods: reserve}
columns:
  - {id: k1, title: K = 1, metric: fleet, args: [--egos, "1", --scenarios, "2"], quick: 1}
""", ran.append)
    assert ran == []


def test_the_cells_of_a_column_share_the_seed_cache(tmp_path):
    """The second cell of a column starts with the seeds the first found (valid_seeds reads OUT/seeds.json), and a
    cell's own finds reach the column; another column starts with none."""
    seen = {}

    def run_one(cell):
        f = Path(cell.out) / "seeds.json"
        seen[cell.out] = json.loads(f.read_text()) if f.is_file() else None
        f.parent.mkdir(parents=True, exist_ok=True)
        f.write_text(json.dumps({**(seen[cell.out] or {}), cell.out[-4:]: True}))
        return {}

    out = _run_tiny_suite(tmp_path, """
name: two
rows:
  - {id: a, label: a, methods: blind}
  - {id: b, label: b, methods: bezier}
columns:
  - {id: c1, title: c1, metric: success, args: [--scenarios, "2"], quick: 1}
  - {id: c2, title: c2, metric: success, args: [--scenarios, "2"], quick: 1}
""", run_one)
    assert seen[str(out / "c1" / "a")] is None and seen[str(out / "c2" / "a")] is None
    assert seen[str(out / "c1" / "b")] == {"c1/a": True}
    assert json.loads((out / "c1" / "seeds.json").read_text()) == {"c1/a": True, "c1/b": True}


@pytest.mark.parametrize(("suite_name", "key", "pick", "picked", "bad", "unknown"), [
    ("fleet", "columns", "paper_k4, busy_k2", ["paper_k4", "busy_k2"], "paper_k2,paper_k3", "paper_k3"),
    ("headline", "rows", "learned,nawaz", ["nawaz", "learned"], "bezier,bezir", "bezir"),  # the suite's order
])
def test_columns_and_rows_pick_in_the_suites_order_and_name_an_unknown_id(suite_name, key, pick, picked, bad,
                                                                          unknown):
    from avp_experiment.headline import suite_columns, suite_rows

    choose = {"columns": suite_columns, "rows": suite_rows}[key]
    suite = load_suite(suite_name)
    assert [c["id"] for c in choose(suite, pick)] == picked
    assert len(choose(suite)) == len(suite[key])
    with pytest.raises(ValueError, match=f"--{key}: unknown .*'{unknown}'"):
        choose(suite, bad)


def test_the_readme_markers_are_required():
    with pytest.raises(ValueError, match="headline:begin"):
        replace_block("no markers here", "| a |\n")
    assert replace_block(f"x\n{BEGIN}\nold\n{END}\ny", "new\n") == f"x\n{BEGIN}\nnew\n{END}\ny"
    begin, end = markers("sensing")
    with pytest.raises(ValueError, match="headline:sensing:begin"):
        replace_block(f"x\n{BEGIN}\nold\n{END}\ny", "new\n", "sensing")
    two = f"{BEGIN}\na\n{END}\n{begin}\nb\n{end}\n"
    assert replace_block(two, "c\n", "sensing") == f"{BEGIN}\na\n{END}\n{begin}\nc\n{end}\n"


def test_a_narrow_table_of_its_own_shows_its_columns_at_fault_and_notes_and_leaves_out_rows_it_lacks():
    """A column with ``readme: NAME`` leaves the README's main table for narrow table NAME; there a cell says its
    at-fault collisions and carries its note's number, and a row that runs in none of its columns is left out."""
    rate = {"k": 3, "n": 100, "percent": 3.0, "ci95": [1.0, 8.5]}
    table = {"suite": "t", "na": {"a": [], "b": ["r2"]},
             "columns": [{"id": "a", "title": "A", "short": "A", "metric": "success"},
                         {"id": "b", "title": "B", "short": "B", "metric": "failed_or_stolen", "readme": "noisy"}],
             "rows": [{"id": "r1", "label": "r1", "short": "r1"}, {"id": "r2", "label": "r2", "short": "r2"}],
             "cells": {"a": {"r1": {"success": rate, "notes": []}, "r2": {"success": rate, "notes": []}},
                       "b": {"r1": {"failed_or_stolen": rate, "at_fault": 2, "notes": ["older code"]}}}}
    assert readme_groups(table) == ["main", "noisy"]
    main = render_narrow(table)
    assert "| A |" in main and "B" not in main and "| r2 | 3.0 [1.0, 8.5] |" in main
    noisy = render_narrow(table, "noisy").splitlines()
    assert noisy[:3] == ["| pick | B |", "|:--|--:|", "| r1 | 3.0 [1.0, 8.5]; 2 at fault<sup>1</sup> |"]
    assert noisy[-1] == "<sup>1</sup> older code." and not any(line.startswith("| r2") for line in noisy)


@pytest.mark.slow
def test_a_suite_runs_resumes_and_tabulates(tmp_path):
    suite = tmp_path / "tiny.yaml"
    suite.write_text("""
name: tiny
rows:
  - {id: bezier, label: "Bézier", methods: bezier, planner: [collision.reactive_steps=0]}
  - {id: blind, label: "blind", methods: blind}
columns:
  - {id: paper, title: "paper: parks", metric: success,
     args: [--protocol, paper, --mode, non-reactive, --scenarios, "50", --t-final, "8"], quick: 1}
""")
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "avp_experiment.runner", "--suite", str(suite), "--quick", "--out", str(out),
           "--workers", "1", "--no-progress"]
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    table = json.loads((out / "tiny.json").read_text())  # OUT/<suite name>.json
    for row in ("bezier", "blind"):
        recs = [json.loads(x) for x in (out / "paper" / row / "episodes.jsonl").read_text().splitlines()]
        assert len(recs) == 1 and recs[0]["method"] == row and recs[0]["seed"] == 0
        assert table["cells"]["paper"][row]["success"]["n"] == 1
    run = json.loads((out / "paper" / "bezier" / "runs.jsonl").read_text().splitlines()[0])
    assert run["options"]["planner_param"] == ["collision.reactive_steps=0"]
    assert "| Bézier |" in (out / "tiny.md").read_text()
    # a second invocation finds every episode done and runs none
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0 and "0 to run" in r.stdout and "1 to run" not in r.stdout
    # the suite's one pool ran blind's episode on the worker bezier's settings had set up: the record is the one
    # blind's cell gives with a pool of its own (timings aside)
    alone = tmp_path / "alone"
    r = subprocess.run([sys.executable, "-m", "avp_experiment.runner", "--protocol", "paper", "--mode", "non-reactive",
                        "--scenarios", "1", "--t-final", "8", "--methods", "blind", "--out", str(alone),
                        "--workers", "1", "--no-progress"], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]

    def bare(folder):
        rec = json.loads((folder / "episodes.jsonl").read_text().splitlines()[0])
        return {k: v for k, v in rec.items() if k not in ("timings", "wall_time", "wall_s")}

    assert bare(out / "paper" / "blind") == bare(alone)


def test_a_fleet_cell_counts_gridlocks_and_spot_losses_per_episode():
    """Every ego of a gridlocked episode carries the episode's gridlock: one episode of eight egos is one gridlock, not
    eight; a spot loss counts once per episode however many egos lost one."""
    from avp_experiment.headline import cell_stats
    from avp_experiment.headline_tables import _cells

    def ego(seed, i, success, lost=0, grid=False, hit=""):
        return {"seed": seed, "mode": "reactive", "ego": i, "success": success, "spots_lost_to_ego": lost,
                "gridlock": grid, "collision_with": hit}

    records = [ego(1, i, i < 5, lost=int(i == 6), grid=True) for i in range(8)]
    records += [ego(2, i, True, lost=1, hit="ego:1" if i == 0 else ("ego:0" if i == 1 else "")) for i in range(8)]
    records += [ego(3, i, True) for i in range(8)]
    s = cell_stats("fleet", records)
    assert s["success"]["k"] == 5 + 8 + 8 and s["success"]["n"] == 24
    assert (s["episodes_with_ego_loss"]["k"], s["episodes_with_ego_loss"]["n"]) == (2, 3)
    assert (s["episodes_with_gridlock"]["k"], s["episodes_with_gridlock"]["n"]) == (1, 3)
    assert s["ego_ego_collisions"] == 2
    text = _cells("fleet", s)[0]
    assert "a gridlock in 1 of 3 episodes" in text and "a spot lost to another ego in 2 of 3 episodes" in text
    assert "2 egos in a collision with another ego" in text
    single = [{"seed": s, "mode": "reactive", "success": s != 2, "collision_with": ""} for s in range(4)]  # K = 1
    s = cell_stats("fleet", single)
    assert s["success"]["k"] == 3 and s["episodes_with_ego_loss"] is s["episodes_with_gridlock"] is None
    assert _cells("fleet", s) == ["75.0 [30.1, 95.4] (4)"]  # no ego-ego or gridlock figure it never measured


def test_a_cell_being_written_or_cut_short_is_left_out_of_the_suite_table(tmp_path):
    """A suite run's table while another `avp experiment` writes one of its cells: that cell is "not run" (its records
    are a run still going); once the run has released the folder, it counts when it has its full size."""
    from avp_experiment.results import being_written, lock_folder

    suite = {"name": "tiny", "rows": [{"id": "blind", "label": "blind", "methods": "blind"}],
             "columns": [{"id": "paper", "title": "paper: parks", "metric": "success",
                          "args": ["--scenarios", "2", "--mode", "reactive"], "quick": 1}]}
    folder = tmp_path / "paper" / "blind"
    folder.mkdir(parents=True)
    (folder / "episodes.jsonl").write_text(json.dumps({"seed": 0, "mode": "reactive", "success": True}) + "\n")
    held = lock_folder(folder)
    try:
        assert being_written(folder)
        assert suite_table(suite, tmp_path)["cells"]["paper"] == {}
    finally:
        held.close()
    assert not being_written(folder)
    # one of the cell's two scenarios: a run that stopped part-way, a cell only at the --quick size (1)
    assert suite_table(suite, tmp_path)["cells"]["paper"] == {}
    assert suite_table(suite, tmp_path, quick=True)["cells"]["paper"]["blind"]["success"]["n"] == 1
    with (folder / "episodes.jsonl").open("a") as f:
        f.write(json.dumps({"seed": 1, "mode": "reactive", "success": False}) + "\n")
    assert suite_table(suite, tmp_path)["cells"]["paper"]["blind"]["success"]["n"] == 2


def test_a_cells_full_size_counts_every_egos_record():
    """--scenarios x modes x the records of each run unit: a plain method one, a fleet of --egos K of each method K,
    a mixed --fleet one per ego."""
    from avp_experiment.headline import full_size

    def size(*args: str, methods: str = "bezier") -> int:
        return full_size({"args": list(args)}, {"methods": methods})

    assert size("--scenarios", "10", "--mode", "reactive") == 10
    assert size("--scenarios", "10", "--mode", "both", methods="bezier,blind") == 40
    assert size("--scenarios", "10", "--mode", "reactive", "--egos", "2", methods="bezier,blind") == 40
    assert size("--scenarios", "10", "--mode", "reactive", "--fleet", "bezier,bezier,blind") == 30
    assert full_size({"args": ["--scenarios", "100", "--mode", "reactive"], "quick": 3}, {"methods": "blind"},
                     quick=True) == 3
