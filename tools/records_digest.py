"""A committed digest of an experiment folder's episode records, and the check of a new run against it.

"Records equal" (docs/experiment.md "Records check") has meant running the old commit again and comparing the two
folders with tools/compare_records.py. A digest lets a fresh clone check it against the committed reference instead:

    python tools/records_digest.py write RUN_DIR DIGEST.json     # after a reference run
    python tools/records_digest.py check RUN_DIR DIGEST.json     # after a change; exit 1 if any record differs

Each (method, seed, mode) episode keeps two things:

* ``sha256``: the hash of the whole record, the machine-dependent timing fields left out (as compare_records.py);
* ``outcome``: status, steps, parked spot, interrupted steps, collision and whether it was the ego's fault, stolen.
  When a hash differs, these say in words what changed; when only the hash differs, a float (an ADE, a parking
  time) moved while the episode did not.

The digest also keeps the run's configuration (``run.json``'s ``config`` and ``intent``). ``check`` refuses a run
made with another configuration, since its records could not be equal. Floating point is bit-equal only on the same
numerics (the wheels of tools/bootstrap.sh on x86-64); a check on other hardware compares outcomes as well, so a
float that differs in its last bit shows up as "hash differs, outcome equal".
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from compare_records import IGNORED  # noqa: E402  (the timing fields, one definition)

from avp_experiment.results import open_records, records_file  # noqa: E402

OUTCOME = ("status", "steps", "parked_spot_id", "interrupted_steps", "collision", "collision_at_fault",
           "spot_stolen")
FORMAT = 1


def _key(r: dict) -> str:
    return f"{r['method']}/{r['seed']}/{r['mode']}"


def _order(key: str) -> tuple:
    method, seed, mode = key.split("/")
    return method, int(seed), mode


def record_digest(r: dict) -> dict:
    """The digest of one episode record: the hash of its machine-independent fields and its outcome."""
    kept = {k: v for k, v in r.items() if k not in IGNORED}
    blob = json.dumps(kept, sort_keys=True, separators=(",", ":")).encode()
    return {"sha256": hashlib.sha256(blob).hexdigest(), "outcome": [r.get(f) for f in OUTCOME]}


def read_run(folder: Path) -> tuple[dict, dict[str, dict]]:
    """(run.json's config and intent hash, the folder's records by key); a clear error for a bad folder."""
    episodes = records_file(folder) if folder.is_dir() else folder / "episodes.jsonl"  # or episodes.jsonl.gz
    if not episodes.is_file():
        raise SystemExit(f"records_digest: {episodes} not found (an `avp experiment --out` folder is needed)")
    records: dict[str, dict] = {}
    with open_records(episodes) as f:
        for n, line in enumerate(f, 1):
            if not line.strip():
                continue
            try:
                r = json.loads(line)
                records[_key(r)] = r
            except (ValueError, KeyError, TypeError) as e:
                raise SystemExit(f"records_digest: {episodes}:{n}: not an episode record ({e})") from None
    run = {}
    if (folder / "run.json").is_file():
        meta = json.loads((folder / "run.json").read_text())
        run = {"config": meta.get("config"), "intent": meta.get("intent")}
    return run, records


def write(folder: Path, out: Path, command: str = "") -> dict:
    run, records = read_run(folder)
    digest = {"format": FORMAT, "command": command, "outcome_fields": list(OUTCOME), **run,
              "episodes": {k: record_digest(records[k]) for k in sorted(records, key=_order)}}
    head = json.dumps({k: v for k, v in digest.items() if k != "episodes"}, indent=1, sort_keys=True)
    eps = ",\n".join(f"  {json.dumps(k)}: {json.dumps(v, sort_keys=True)}" for k, v in digest["episodes"].items())
    out.write_text(head[:-2] + ',\n "episodes": {\n' + eps + "\n }\n}\n")  # one episode a line: diffs read well
    return digest


def _filled(field: str, value):
    """A run's ``config`` with the RunConfig fields added since a digest was written at their defaults (as
    avp_experiment resumes such a folder); other fields as they are."""
    if field != "config" or not isinstance(value, dict):
        return value
    from dataclasses import asdict

    from avp_episode.run_config import RunConfig

    return {**asdict(RunConfig()), **value}


def check(folder: Path, ref: Path) -> tuple[int, list[str]]:
    """Compare a run with a digest; returns (exit status, report lines)."""
    try:
        want = json.loads(ref.read_text())
    except FileNotFoundError:
        raise SystemExit(f"records_digest: {ref} not found (a digest written by `records_digest.py write`)") from None
    except ValueError as e:
        raise SystemExit(f"records_digest: {ref}: not a digest ({e})") from None
    if want.get("format") != FORMAT:
        return 2, [f"{ref}: format {want.get('format')!r}, this tool reads {FORMAT}"]
    run, records = read_run(folder)
    for field in ("config", "intent"):
        if field in want and _filled(field, run.get(field)) != _filled(field, want[field]):
            return 2, [f"{folder}/run.json: {field} differs from the digest's, so the records cannot be compared",
                       f"  digest: {json.dumps(want[field], sort_keys=True)}",
                       f"  run:    {json.dumps(run.get(field), sort_keys=True)}"]
    ref_eps = want["episodes"]
    common = sorted(set(ref_eps) & set(records))
    missing = sorted(set(ref_eps) - set(records))
    equal, outcome_only, changed = 0, [], []
    for k in common:
        got = record_digest(records[k])
        if got["sha256"] == ref_eps[k]["sha256"]:
            equal += 1
        elif got["outcome"] == ref_eps[k]["outcome"]:
            outcome_only.append(k)
        else:
            changed.append(k)
    lines = [f"{len(common)} episodes in both, {equal} equal, {len(outcome_only)} with the same outcome but another "
             f"float, {len(changed)} with another outcome, {len(missing)} missing from {folder}"]
    for k in changed[:10]:
        old, new = ref_eps[k]["outcome"], record_digest(records[k])["outcome"]
        moved = (f"{f} {a!r} -> {b!r}" for f, a, b in zip(OUTCOME, old, new, strict=False) if a != b)
        lines.append(f"  {k}: " + ", ".join(moved))
    for k in outcome_only[:5]:
        lines.append(f"  {k}: outcome equal, record hash differs")
    return (1 if outcome_only or changed or missing else 0), lines


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    w = sub.add_parser("write", help="write the digest of RUN_DIR's records")
    w.add_argument("run_dir", type=Path)
    w.add_argument("digest", type=Path)
    w.add_argument("--command", default="", help="the command that made the run, kept in the digest")
    c = sub.add_parser("check", help="compare RUN_DIR's records with DIGEST; exit 1 if any differs")
    c.add_argument("run_dir", type=Path)
    c.add_argument("digest", type=Path)
    a = ap.parse_args(argv)
    if a.cmd == "write":
        d = write(a.run_dir, a.digest, a.command)
        print(f"{a.digest}: {len(d['episodes'])} episodes")
        return 0
    status, lines = check(a.run_dir, a.digest)
    print("\n".join(lines))
    return status


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
