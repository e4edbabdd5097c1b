"""Where the ego's steps went, per results folder: the mean steps of an episode in each planner mode and the mean
idle steps by their cause, from each record's decision trace (docs/results/sensing/README.md); then how the ego drove:
its reversals and new plans an episode, and how many of its timeouts end frozen (a last idle spell of at least
FROZEN_STEPS steps) rather than still driving.

    python tools/idle_causes.py NAME=FOLDER[:METHOD] | NAME=headline:COLUMN/ROW ...

FOLDER holds episodes.jsonl or episodes.jsonl.gz (or is one such file); METHOD picks one method's records (default:
all); headline:COLUMN/ROW reads the records the headline suite commits for that cell (config/suites/headline.yaml:
exact sensing). Prints a markdown table, one row per item, with the outcomes of its episodes.
"""

from __future__ import annotations

import argparse
import gzip
import json
import sys
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MODES = ("explore", "park", "idle", "detour", "wait_and_go", "evasive")
CAUSES = ("vehicle:standing", "vehicle:towards", "vehicle:away", "vehicle:braking", "pedestrian:standing",
          "pedestrian:towards", "pedestrian:away", "static")


def records(folder: Path, method: str | None) -> list[dict]:
    """The records of a results folder (or of one .jsonl / .jsonl.gz file), of ``method`` only when given."""
    path = folder if folder.is_file() else folder / "episodes.jsonl.gz"
    path = path if path.is_file() else folder / "episodes.jsonl"
    opener = gzip.open if path.suffix == ".gz" else open
    with opener(path, "rt") as f:
        return [r for r in map(json.loads, f) if method is None or r["method"] == method]


def row(name: str, recs: list[dict]) -> str:
    status = Counter(r["status"] for r in recs)
    recs = [r for r in recs if (r.get("decision_trace") or {}).get("steps_by_mode")]  # older records have none
    modes, idle = Counter(), Counter()
    for r in recs:
        trace = r.get("decision_trace") or {}
        modes.update(trace.get("steps_by_mode", {}))
        idle.update(trace.get("idle_steps_by_cause", {}))
    n = max(len(recs), 1)
    cells = [f"{modes[m] / n:.1f}" for m in MODES] + [f"{idle[c] / n:.1f}" for c in CAUSES]
    outcome = ", ".join(f"{k} {v}" for k, v in sorted(status.items()))
    return f"| {name} | {len(recs)} | " + " | ".join(cells) + f" | {outcome} |"


FROZEN_STEPS = 100  # steps (10 s): a timeout whose last idle spell is this long ended frozen


def driving(name: str, recs: list[dict]) -> str:
    """One row of the second table: reversals and new plans an episode, timeouts, those that ended frozen."""
    n = max(len(recs), 1)
    rev = sum(r.get("reversals", 0) for r in recs) / n
    plans = sum((r.get("timings") or {}).get("planning_steps", 0) for r in recs) / n
    timeouts = [r for r in recs if r["status"] == "timeout"]
    frozen = sum(max(((r.get("decision_trace") or {}).get("idle_spells") or [{"start_step": 0, "steps": 0}]),
                     key=lambda sp: sp["start_step"])["steps"] >= FROZEN_STEPS for r in timeouts)
    return f"| {name} | {rev:.2f} | {plans:.1f} | {len(timeouts)} | {frozen} |"


def _by_spot(both: list[tuple]) -> str:
    """The parking time's mean change split by whether both parked in the same spot, and the share of its total
    from the episodes that changed by more than 10 s."""
    out = []
    for label, same in (("same spot", True), ("another", False)):
        sel = [b for b in both if (b[1] == b[3]) == same]
        if sel:
            out.append(f"{label} {len(sel)}: {sum(b[2] - b[0] for b in sel) / len(sel):+.2f} s")
    total = sum(b[2] - b[0] for b in both)
    tail = sum(b[2] - b[0] for b in both if abs(b[2] - b[0]) > 10)
    n_tail = sum(abs(b[2] - b[0]) > 10 for b in both)
    return f"; {', '.join(out)}; {tail:+.0f} of the {total:+.0f} s from the {n_tail} that changed by > 10 s"


def transitions(first: list[dict], other: list[dict]) -> str:
    """How the outcomes of the seeds both hold changed from ``first`` to ``other``."""
    a = {(r["seed"], r["mode"]): r["status"] for r in first}
    moves = Counter(f"{a[k]} -> {r['status']}" for r in other if (k := (r["seed"], r["mode"])) in a
                    and a[k] != r["status"])
    shared = sum((r["seed"], r["mode"]) in a for r in other)
    times = {(r["seed"], r["mode"]): (r["parking_time"], r.get("parked_spot_id")) for r in first
             if r["status"] == "success"}
    both = [(*times[k], r["parking_time"], r.get("parked_spot_id")) for r in other
            if r["status"] == "success" and (k := (r["seed"], r["mode"])) in times]
    paired = (f"; on the {len(both)} both park, parking time {sum(b[0] for b in both) / len(both):.1f} -> "
              f"{sum(b[2] for b in both) / len(both):.1f} s (longer on {sum(b[2] > b[0] for b in both)}"
              f"{_by_spot(both)})" if both else "")
    return (f"{shared} shared seeds: " + (", ".join(f"{m} {n}" for m, n in sorted(moves.items())) or "no change")
            + paired)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("folders", nargs="+", help="NAME=FOLDER[:METHOD]")
    args = ap.parse_args(argv)
    head = ["folder", "n traced", *(f"{m}" for m in MODES), *(f"idle: {c}" for c in CAUSES), "outcomes"]
    print("| " + " | ".join(head) + " |")
    print("|---|" + "--:|" * (len(head) - 2) + "---|")
    items = []
    for item in args.folders:
        name, _, rest = item.partition("=")
        if rest.startswith("headline:"):
            from avp_experiment.headline import committed_records, load_suite

            column, _, cell = rest.removeprefix("headline:").partition("/")
            recs = list(committed_records(load_suite("headline")["committed"][column][cell], ROOT)[0])
        else:
            folder, _, method = rest.partition(":")
            recs = records(Path(folder), method or None)
        items.append((name, recs))
        print(row(name, recs))
    print()
    print("| folder | reversals an episode | new plans an episode | timeouts | of them frozen at the end |")
    print("|---|--:|--:|--:|--:|")
    for name, recs in items:
        print(driving(name, recs))
    print()
    for name, recs in items[1:]:
        print(f"* {items[0][0]} -> {name}, outcomes that changed on the {transitions(items[0][1], recs)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
