"""Run the DDS tests again and again, optionally beside CPU hogs, to catch races before CI does.

    python tools/stress_dds.py [--runs 10] [--hogs 2] [--workers 4] [--out out/stress_dds] [-- PYTEST ARGS ...]
    make stress-dds RUNS=10 HOGS=2 [TEST_WORKERS=4]

Each run is one ``python -m pytest -m dds tests`` (with ``--workers N`` > 0: ``-n N --dist loadgroup``, N test
processes at once, as ``make test`` runs them) (the tests that start node processes or talk over DDS: the
``dds`` marker, tests/conftest.py), in a fresh process. ``--hogs H`` starts H busy-loop processes for the whole loop,
as a loaded CI machine would be. Every run's counts and failed test ids are appended to OUT/runs.jsonl and its
pytest output kept as OUT/run_<i>.log; the last line printed is the total. Exit status 1 if any run failed.

A race shows up as a test that fails one run in several: a message published once before discovery matched its
reader, a command sent before the node's subscription matched, a fixed sleep that a loaded machine outlasts.
Wait by condition instead (docs/architecture.md, "Faults").
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
_COUNT = re.compile(r"(\d+) (passed|failed|error|errors|skipped)")


def summarise(output: str) -> dict[str, int]:
    """The counts of pytest's last summary line, e.g. {'passed': 53, 'failed': 1}."""
    counts: dict[str, int] = {}
    for n, what in _COUNT.findall(output.strip().splitlines()[-1] if output.strip() else ""):
        counts["error" if what == "errors" else what] = int(n)
    return counts


def hog() -> subprocess.Popen:
    """One process that keeps a core busy until killed."""
    return subprocess.Popen([sys.executable, "-c", "while True: pass"])


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    extra: list[str] = []
    if "--" in argv:
        i = argv.index("--")
        argv, extra = argv[:i], argv[i + 1:]
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=10, help="how many times to run the DDS tests [10]")
    ap.add_argument("--hogs", type=int, default=0, help="busy-loop processes beside the tests [0]")
    ap.add_argument("--workers", type=int, default=0,
                    help="test processes at once (pytest-xdist, as make test); 0 = one after another [0]")
    ap.add_argument("--out", type=Path, default=ROOT / "out/stress_dds", help="where the logs go")
    args = ap.parse_args(argv)
    if args.runs < 1 or args.hogs < 0 or args.workers < 0:
        ap.error("--runs must be >= 1, --hogs and --workers >= 0")
    if args.workers:
        extra = ["-n", str(args.workers), "--dist", "loadgroup", *extra]
    args.out.mkdir(parents=True, exist_ok=True)
    hogs = [hog() for _ in range(args.hogs)]
    failed_runs = 0
    try:
        for i in range(args.runs):
            t0 = time.monotonic()
            cmd = [sys.executable, "-m", "pytest", "-q", "-m", "dds", "-p", "no:cacheprovider", "tests", *extra]
            r = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, env=dict(os.environ))
            out = r.stdout + r.stderr
            (args.out / f"run_{i}.log").write_text(out)
            counts = summarise(r.stdout)
            failures = sorted(set(re.findall(r"^(?:FAILED|ERROR) (\S+)", r.stdout, re.M)))
            rec = {"run": i, "rc": r.returncode, "wall_s": round(time.monotonic() - t0, 1), "hogs": args.hogs,
                   "workers": args.workers,
                   "loadavg_end": [round(x, 2) for x in os.getloadavg()], **counts, "failures": failures}
            with (args.out / "runs.jsonl").open("a") as f:
                f.write(json.dumps(rec) + "\n")
            failed_runs += r.returncode != 0
            print(f"run {i + 1}/{args.runs}: rc {r.returncode}, {counts}, {rec['wall_s']} s, load "
                  f"{rec['loadavg_end'][1]}"
                  + (f", failed: {', '.join(failures)}" if failures else ""), flush=True)
    finally:
        for h in hogs:
            h.kill()
            h.wait()
    print(f"{args.runs - failed_runs} of {args.runs} runs passed ({args.hogs} CPU hogs beside them)")
    return 1 if failed_runs else 0


if __name__ == "__main__":
    sys.exit(main())
