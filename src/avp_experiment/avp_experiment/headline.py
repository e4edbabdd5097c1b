"""The headline suite: one command for every figure of the README's results table.

    avp experiment --suite headline [--quick] --out OUT [--workers N] [--backend ray]   # run it (resumable)
    python -m avp_experiment.headline table OUT            # OUT/headline.json + OUT/headline.md from that run
    python -m avp_experiment.headline table --committed --json docs/results/headline.json --readme README.md

The suite (``config/suites/headline.yaml``) is a grid: rows are what a user can pick (a method, or the paper's method
with a planner profile), columns the settings it is judged in; a cell is one ``avp experiment`` run of the column's
arguments then the row's, into ``OUT/<column>/<row>/``, so an interrupted suite resumes cell by cell and episode by
episode. ``--quick`` runs each column's ``quick`` scenario count (minutes, for a contributor).

The table is computed from records only: from a suite's folder, or (``--committed``) from the committed records the
suite file names per cell. The README holds the committed table between the markers ``<!-- headline:begin -->`` and
``<!-- headline:end -->``, and a column with ``readme: NAME`` in a narrow table of its own between
``<!-- headline:NAME:begin -->`` and ``<!-- headline:NAME:end -->`` (the realistic-sensing columns);
tests/test_headline.py fails when they and the committed records disagree. Rates carry 95 %
Wilson intervals, means a normal 95 % interval (1.96 standard errors).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import yaml

from avp_episode.metrics import Z95, wilson
from avp_experiment.headline_tables import (  # noqa: F401 - re-exported: the README's tables
    BEGIN,
    END,
    MAIN,
    markers,
    readme_groups,
    render,
    render_narrow,
    replace_block,
    write_table,
)
from avp_experiment.results import SEEDS_FILE, being_written, read_results

METRICS = ("success", "failed_or_stolen", "busy", "fleet")


def suites_dir() -> Path:
    """The shipped suites (package share directory, else the source tree)."""
    from avp_common.share import SRC, package_share

    d = package_share("avp_experiment") / "config" / "suites"
    return d if d.is_dir() else SRC / "avp_experiment" / "config" / "suites"


def load_suite(name_or_path: str = "headline") -> dict:
    """A suite by name (``config/suites/<name>.yaml``) or path; ValueError names the file and what is wrong."""
    p = Path(name_or_path)
    if not p.suffix:
        p = suites_dir() / f"{name_or_path}.yaml"
    if not p.is_file():
        shipped = sorted(q.stem for q in suites_dir().glob("*.yaml"))
        raise ValueError(f"unknown suite {name_or_path!r}; shipped: {shipped}")
    suite = yaml.safe_load(p.read_text())
    rows, cols = suite.get("rows"), suite.get("columns")
    if not isinstance(rows, list) or not isinstance(cols, list) or not rows or not cols:
        raise ValueError(f"{p}: a suite has non-empty lists 'rows' and 'columns'")
    for c in cols:
        if c.get("metric") not in METRICS:
            raise ValueError(f"{p}: column {c.get('id')!r}: metric must be one of {METRICS}")
    ids = {r["id"] for r in rows}
    for col, cells in (suite.get("committed") or {}).items():
        if col not in {c["id"] for c in cols} or not set(cells) <= ids:
            raise ValueError(f"{p}: committed.{col}: unknown column or row {sorted(set(cells) - ids)}")
    suite["source"] = str(p)
    return suite


def runs_in(row: Mapping, col: Mapping) -> bool:
    return col["id"] in row.get("only", [col["id"]])


def suite_method(name: str) -> str:
    """A row's method: a name as it is; a profile file (``*.yaml``) given relative, under the suites' directory
    (``config/suites/methods/*.yaml``: methods that only a suite runs)."""
    name = name.strip()
    if name.endswith((".yaml", ".yml")) and not Path(name).is_absolute():
        return str(suites_dir() / name)
    return name


def cell_argv(col: Mapping, row: Mapping, quick: bool) -> list[str]:
    """The ``avp experiment`` arguments of one cell (the column's, then the row's; no --out)."""
    argv = [str(a) for a in col["args"]]
    if quick:
        i = argv.index("--scenarios")
        argv[i + 1] = str(col["quick"])
    argv += ["--methods", ",".join(suite_method(m) for m in str(row["methods"]).split(","))]
    for kv in row.get("planner", []):
        argv += ["--planner-param", kv]
    for kv in row.get("tracker", []):  # the tracker's settings (noisy sensing columns only)
        argv += ["--tracker-param", kv]
    return argv


def full_size(col: Mapping, row: Mapping, quick: bool = False) -> int:
    """The records a finished cell holds: ``--scenarios`` x modes (``--mode``) x the egos of every run unit (a
    method, a fleet of ``--egos`` of it or the ``--fleet``; a fleet records each ego, as the runner counts them). A
    folder with fewer is a run that stopped part-way, not a cell."""
    from avp_episode.fleet import fleet_names, run_units
    from avp_experiment.arguments import MODES, add_arguments

    p = argparse.ArgumentParser(add_help=False)
    add_arguments(p)
    a = p.parse_args(cell_argv(col, row, quick))
    units = run_units([m.strip() for m in a.methods.split(",") if m.strip()], a.egos, a.fleet)
    return a.scenarios * len(MODES[a.mode]) * sum(max(1, len(fleet_names(u))) for u in units)


def run_suite(args: argparse.Namespace, run_one: Callable[[argparse.Namespace], dict],
              parse: Callable[[list[str]], argparse.Namespace], resolve: Callable) -> dict:
    """Every cell of ``args.suite`` into ``args.out/<column>/<row>``; the table of what came out last. ``resolve``
    (the runner's ``resolve_methods``) checks every cell's methods before any cell runs."""
    suite = load_suite(args.suite)
    out = Path(args.out)
    report: dict = {"cells": 0, "ran": 0, "errors": []}  # the runner's report: errors lists the failed episodes
    rows = suite_rows(suite, getattr(args, "rows", ""))
    cells = [(col, row, parse(cell_argv(col, row, args.quick)))
             for col in suite_columns(suite, getattr(args, "columns", "")) for row in rows if runs_in(row, col)]
    _check_cells(cells, getattr(args, "transport", "inproc"), resolve)  # before any cell runs, not hours into it
    for col, row, cell in cells:
        for keep in ("workers", "backend", "address", "no_progress", "transport", "intent_weights",
                     "shared_pool"):  # the last: one pool for every cell (avp_episode.pool)
            setattr(cell, keep, getattr(args, keep, None))
        cell.out = str(out / col["id"] / row["id"])
        print(f"[avp experiment] suite {suite['name']}: {col['id']} / {row['id']}", file=sys.stderr, flush=True)
        _share_seeds(out / col["id"] / SEEDS_FILE, Path(cell.out) / SEEDS_FILE)
        r = run_one(cell)
        _share_seeds(Path(cell.out) / SEEDS_FILE, out / col["id"] / SEEDS_FILE)
        report["cells"] += 1
        report["ran"] += r.get("ran", 0)
        report["errors"] += r.get("errors") or []
    table = suite_table(suite, out, quick=args.quick)
    write_table(table, out / f"{suite['name']}.json", out / f"{suite['name']}.md")
    print(f"[avp experiment] suite {suite['name']}: {out / (suite['name'] + '.md')}", file=sys.stderr)
    return report


def _share_seeds(src: Path, dst: Path) -> None:
    """Copy a column's seed cache to a cell (or back) where ``dst`` lacks seeds ``src`` has. The cells of a column
    share the lot and simulator settings (rows set methods and planner parameters only), so a seed builds a scenario
    in all or none of them; the busy lot spends seconds a seed finding out."""
    if not src.is_file():
        return
    known = json.loads(src.read_text())
    have = json.loads(dst.read_text()) if dst.is_file() else {}
    if set(known) - set(have):
        dst.parent.mkdir(parents=True, exist_ok=True)
        dst.write_text(json.dumps({**known, **have}, sort_keys=True))


def _check_cells(cells: Sequence[tuple[Mapping, Mapping, argparse.Namespace]], transport: str,
                 resolve: Callable) -> None:
    """ValueError naming every cell whose methods the runner would skip (say ``reserve`` with one ego)."""
    bad = []
    for col, row, cell in cells:
        _, skipped = resolve(cell.methods, transport=transport, egos=cell.egos)
        bad += [f"{col['id']} / {row['id']}: {name}: {why}" for name, why in skipped.items()]
    if bad:
        raise ValueError("suite cells that cannot run (give the row `only: [columns]`): " + "; ".join(bad))


def suite_columns(suite: Mapping, only: str = "") -> list[Mapping]:
    """The suite's columns, or those ``only`` names (comma-separated ids); ValueError names an unknown id."""
    return _pick(suite, "columns", only)


def suite_rows(suite: Mapping, only: str = "") -> list[Mapping]:
    """The suite's rows, or those ``only`` names (comma-separated ids), in the suite's order; ValueError names an
    unknown id."""
    return _pick(suite, "rows", only)


def _pick(suite: Mapping, key: str, only: str) -> list[Mapping]:
    if not only:
        return list(suite[key])
    ids = [c["id"] for c in suite[key]]
    wanted = [w.strip() for w in only.split(",") if w.strip()]
    unknown = [w for w in wanted if w not in ids]
    if unknown or not wanted:
        raise ValueError(f"--{key}: unknown {key[:-1]}(s) {unknown} of suite {suite['name']!r}; it has {ids}")
    return [c for c in suite[key] if c["id"] in wanted]


# ------------------------------------------------------------------------------------------ statistics


def _rate(k: int, n: int) -> dict:
    lo, hi = wilson(k, n)
    return {"k": k, "n": n, "percent": round(100.0 * k / n, 1), "ci95": [round(100 * lo, 1), round(100 * hi, 1)]}


def _mean(values: Sequence[float]) -> dict:
    n = len(values)
    m = sum(values) / n
    sd = math.sqrt(sum((v - m) ** 2 for v in values) / (n - 1)) if n > 1 else 0.0
    half = Z95 * sd / math.sqrt(n)
    return {"n": n, "mean": round(m, 1), "ci95": [round(m - half, 1), round(m + half, 1)]}


def cell_stats(metric: str, records: Sequence[Mapping]) -> dict | None:
    """The figures of one cell from its records (None without records)."""
    if not records:
        return None
    n = len(records)
    if metric == "success":
        return {"success": _rate(sum(bool(r["success"]) for r in records), n)}
    if metric == "failed_or_stolen":
        return {"failed_or_stolen": _rate(sum((not r["success"]) or bool(r["spot_stolen"]) for r in records), n),
                "at_fault": sum(bool(r.get("collision_at_fault")) for r in records)}
    if metric == "busy":
        return {"success": _rate(sum(bool(r["success"]) for r in records), n),
                "spot_stolen": _rate(sum(bool(r["spot_stolen"]) for r in records), n),
                "at_fault": sum(bool(r.get("collision_at_fault")) for r in records),
                "interrupted_steps": _mean([float(r["interrupted_steps"]) for r in records])}
    # fleet: parks per ego-episode; an ego-ego spot loss and a gridlock per episode (any ego's record says so: every
    # ego of a gridlocked episode carries it; docs/results/fleet); the egos that collided with another ego. A single
    # ego's records carry no such fields (its episode is the single-ego one): those figures are then None, not 0.
    if not any("spots_lost_to_ego" in r for r in records):
        return {"success": _rate(sum(bool(r["success"]) for r in records), n), "episodes_with_ego_loss": None,
                "ego_ego_collisions": None, "episodes_with_gridlock": None}
    lost: dict[tuple, bool] = {}
    locked: dict[tuple, bool] = {}
    for r in records:
        key = (r["seed"], r["mode"])
        lost[key] = lost.get(key, False) or bool(r.get("spots_lost_to_ego"))
        locked[key] = locked.get(key, False) or bool(r.get("gridlock"))
    return {"success": _rate(sum(bool(r["success"]) for r in records), n),
            "episodes_with_ego_loss": _rate(sum(lost.values()), len(lost)),
            "ego_ego_collisions": sum(str(r.get("collision_with", "")).startswith("ego") for r in records),
            "episodes_with_gridlock": _rate(sum(locked.values()), len(locked))}


def _select(records: Sequence[Mapping], spec: Mapping) -> list[Mapping]:
    lo, hi = spec.get("seeds", [-math.inf, math.inf])
    mode = spec.get("mode", "").replace("-", "_")
    return [r for r in records if r["method"] == spec["method"] and lo <= r["seed"] <= hi
            and (not mode or r["mode"] == mode)]


def committed_records(specs: Sequence[Mapping], root: Path) -> tuple[list[Mapping], list[str]]:
    """The records a committed cell names (several files are one cell: their seeds must not overlap), its notes."""
    records: list[Mapping] = []
    seen: set[tuple] = set()
    for spec in specs:
        rs = _select(read_results(root / spec["file"]), spec)
        if not rs:
            raise ValueError(f"{spec['file']}: no record of method {spec['method']!r} in the seeds named")
        for r in rs:
            key = (r["seed"], r["mode"], r.get("ego"))
            if key in seen:
                raise ValueError(f"{spec['file']}: seed {r['seed']} ({r['mode']}) is in two files of one cell")
            seen.add(key)
        records += rs
    return records, [s["note"] for s in specs if s.get("note")]


def suite_table(suite: Mapping, out: Path | None = None, root: Path | None = None, quick: bool = False) -> dict:
    """{columns, rows, cells: {column: {row: stats+sources}}} from a suite run (``out``, run with ``--quick`` or not;
    a cell whose folder an ``avp experiment`` is writing now, or that holds fewer records than :func:`full_size`, is
    left out) or the committed records (``root``: the repository)."""
    cells: dict[str, dict] = {}
    for col in suite["columns"]:
        cells[col["id"]] = {}
        for row in suite["rows"]:
            if not runs_in(row, col):
                continue
            if root is not None:
                specs = suite.get("committed", {}).get(col["id"], {}).get(row["id"])
                if not specs:
                    continue
                records, notes = committed_records(specs, root)
                sources = sorted({s["file"] for s in specs})
            else:
                folder = out / col["id"] / row["id"]
                if being_written(folder):  # a cell still running is "not run" until it ends
                    continue
                records, notes, sources = read_results(folder), [], [str(folder)]
                if len(records) < full_size(col, row, quick):  # a run that stopped part-way
                    continue
            stats = cell_stats(col["metric"], records)
            if stats is not None:
                cells[col["id"]][row["id"]] = {**stats, "sources": sources, "notes": notes}
    return {"suite": suite["name"],
            "columns": [{**{k: c[k] for k in ("id", "title", "metric")}, "short": c.get("short", c["title"]),
                         **({"readme": c["readme"]} if c.get("readme", MAIN) != MAIN else {})}
                        for c in suite["columns"]],
            "rows": [{"id": r["id"], "label": r["label"], "short": r.get("short", r["label"])} for r in suite["rows"]],
            "cells": cells,
            "na": {c["id"]: [r["id"] for r in suite["rows"] if not runs_in(r, c)] for c in suite["columns"]}}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m avp_experiment.headline", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    t = sub.add_parser("table", help="the table of a suite run (OUT) or of the committed records (--committed)")
    t.add_argument("out", nargs="?", help="a suite's --out folder")
    t.add_argument("--suite", default="headline")
    t.add_argument("--committed", action="store_true", help="from the committed records the suite file names")
    t.add_argument("--root", default=".", help="the repository (committed records are under it) [.]")
    t.add_argument("--json", help="write the table's JSON here [OUT/headline.json]")
    t.add_argument("--quick", action="store_true", help="OUT was run with --quick: the cells are that size")
    t.add_argument("--readme", help="replace the narrow table (a rate [interval] a cell) between the headline "
                   "markers of this file")
    t.add_argument("--results-page", help="replace the full table (counts, sub-columns, footnotes) between the "
                   "headline markers of this file")
    args = ap.parse_args(argv)
    if args.committed == bool(args.out):
        ap.error("give a suite's OUT folder or --committed, one of them")
    try:
        suite = load_suite(args.suite)
        table = (suite_table(suite, root=Path(args.root)) if args.committed
                 else suite_table(suite, Path(args.out), quick=args.quick))
    except (ValueError, OSError) as exc:
        print(f"[headline] {exc}", file=sys.stderr)
        return 2
    json_path = Path(args.json) if args.json else (Path(args.out) / f"{suite['name']}.json" if args.out else None)
    if json_path:
        write_table(table, json_path, json_path.with_suffix(".md"))
    if args.readme:
        p = Path(args.readme)
        text = p.read_text()
        for group in readme_groups(table):
            text = replace_block(text, render_narrow(table, group), group)
        p.write_text(text)
    if args.results_page:
        p = Path(args.results_page)
        p.write_text(replace_block(p.read_text(), render(table)))
    if not json_path and not args.readme and not args.results_page:
        print(render(table), end="")
    return 0


if __name__ == "__main__":
    sys.exit(main())
