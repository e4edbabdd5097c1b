"""Compare two experiment folders' episode records, timing fields aside (docs/experiment.md "Records check").

    python tools/compare_records.py OUT_BEFORE OUT_AFTER [--new-fields]

Prints how many (method, seed, mode) episodes both hold (with several egos: (method, seed, mode, ego)),
how many are equal, and the first differences; exits 1 if any record differs or the after folder lacks an episode
the before folder has. ``--new-fields``: a field that
no record of OUT_BEFORE has (added to the records since, e.g. ``lot`` and ``collision_at_fault``)
is left out of the comparison, and its values in OUT_AFTER are counted.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from avp_experiment.results import open_records

IGNORED = {"timings", "wall_time", "wall_s", "transport"}  # machine-dependent fields


def _records(folder: str) -> dict[tuple, dict]:
    out = {}
    with open_records(Path(folder)) as lines:  # its episodes.jsonl or episodes.jsonl.gz
        for line in lines:
            if line.strip():
                r = json.loads(line)
                key = (r["method"], r["seed"], r["mode"]) + ((r["ego"],) if "ego" in r else ())  # a record per ego
                out[key] = {k: v for k, v in r.items() if k not in IGNORED}
    return out


def main(argv: list[str]) -> int:
    new_fields = "--new-fields" in argv
    argv = [a for a in argv if a != "--new-fields"]
    before, after = _records(argv[0]), _records(argv[1])
    common = sorted(set(before) & set(after))
    if new_fields:
        old = set().union(*(r.keys() for r in before.values()))
        added = sorted(set().union(*(r.keys() for r in after.values())) - old)
        for f in added:
            values: dict[str, int] = {}
            for r in after.values():
                values[json.dumps(r.get(f), sort_keys=True)] = values.get(json.dumps(r.get(f), sort_keys=True), 0) + 1
            print(f"new field {f!r} (not compared): {values}")
        after = {k: {f: v for f, v in r.items() if f in old} for k, r in after.items()}
    diffs = [k for k in common if before[k] != after[k]]
    missing = sorted(set(before) - set(after))
    print(f"{len(common)} episodes in both, {len(common) - len(diffs)} equal, {len(diffs)} differ, "
          f"{len(missing)} missing from {argv[1]}")
    for k in diffs[:10]:
        fields = sorted(f for f in before[k].keys() | after[k].keys() if before[k].get(f) != after[k].get(f))
        print("  ", k, {f: (before[k].get(f), after[k].get(f)) for f in fields})
    return 1 if diffs or missing else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
