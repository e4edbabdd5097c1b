"""Why the episodes of a run time out — steps per mode and idle steps per cause of the timeouts,
per method, from the records' ``decision_trace`` (avp_motion.trace).

    python tools/trace_table.py RECORDS.jsonl [RECORDS.jsonl ...] [--status timeout]

Each file's records keep their method name; a file name other than episodes.jsonl(.gz) labels its records
``<method>+<file stem>`` unless the stem is ``diag`` (so that variants of one method stay apart).
"""

from __future__ import annotations

import json
import sys
from collections import Counter
from pathlib import Path

from avp_experiment.results import open_records, records_stem


def load(paths: list[str]) -> dict[str, list[dict]]:
    out: dict[str, list[dict]] = {}
    for p in paths:
        stem = records_stem(p)
        with open_records(Path(p)) as lines:  # .jsonl or .jsonl.gz
            for line in lines:
                if line.strip():
                    r = json.loads(line)
                    label = r["method"] if stem in ("episodes", "diag") else f"{r['method']}+{stem}"
                    out.setdefault(label, []).append(r)
    return out


def main(argv: list[str]) -> int:
    status = "timeout"
    if "--status" in argv:
        i = argv.index("--status")
        status, argv = argv[i + 1], argv[:i] + argv[i + 2:]
    runs = load(argv)
    print("| method | episodes | success | timeouts | mean interrupted steps | timeout steps by mode | idle steps of "
          "the timeouts by cause | longest idle spell of each timeout [s] |\n|---|--:|--:|--:|--:|---|---|---|")
    for label, recs in runs.items():
        bad = [r for r in recs if r["status"] == status and "decision_trace" in r]
        modes, causes = Counter(), Counter()
        for r in bad:
            modes.update(r["decision_trace"]["steps_by_mode"])
            causes.update(r["decision_trace"]["idle_steps_by_cause"])
        pct = lambda c: ", ".join(f"{k} {100 * v / max(1, sum(c.values())):.0f} %" for k, v in c.most_common())  # noqa: E731
        spells = sorted(round(r["decision_trace"]["longest_idle_steps"] / 10, 1) for r in bad)
        inter = sum(r["interrupted_steps"] for r in recs) / max(1, len(recs))
        print(f"| {label} | {len(recs)} | {sum(r['success'] for r in recs)} | {len(bad)} | {inter:.1f} | "
              f"{pct(modes)} | {pct(causes)} | {spells} |")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
