"""``avp why``: why the ego was not moving — the idle spells of one episode with their causes (docs/stuck_ego.md).

From a **bag** (a directory or .mcap file): the planner's ``~/debug/decision`` trace (avp_msgs/DecisionTrace)
of the last episode in it. From a **run** (the ``--out`` folder of ``avp experiment``, or a file of episode records
such as ``tools/run_seeds.py`` writes): the ``decision_trace`` of the record of ``--seed``/``--method``/``--mode``.
Prints the steps per mode, the idle steps per cause and the longest idle spells (when, how long, the main cause, the
blocking agents).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from avp_motion.trace import DecisionTrace, spells_text

TRACE_TOPIC = "/avp/avp_planner/debug/decision"


def trace_topic(ego: int | None = None) -> str:
    """The planner's trace topic: of the one-ego graph, or of ego ``ego`` among several (/avp/ego<i>/...)."""
    return TRACE_TOPIC if ego is None else TRACE_TOPIC.replace("/avp/", f"/avp/ego{int(ego)}/", 1)


def trace_from_bag(bag: Path, ego: int | None = None) -> tuple[dict, float]:
    """(trace summary, dt) of the last episode in ``bag`` (of ego ``ego`` of a graph of several); ValueError when it
    holds no decision trace."""
    from avp_bag.reader import BagReader
    from avp_planner.trace_msg import trace_from_msg

    topic = trace_topic(ego)
    reader = BagReader(bag)
    steps: dict[int, tuple] = {}
    for _topic, msgtype, _t, raw in reader.messages((topic,)):
        step = trace_from_msg(reader.deserialize(raw, msgtype))
        if steps and step[0] < min(steps):
            steps = {}  # a new episode: keep the last one
        steps[step[0]] = step
    if not steps:
        raise ValueError(f"{bag}: no {topic} messages (recorded by avp demo/record since v0.3.0"
                         + ("; a graph of several egos has /avp/ego<i>/...: give --ego i)" if ego is None else ")"))
    trace = DecisionTrace(0.1)
    for k in sorted(steps):
        trace.add_step(*steps[k])
    return trace.summary(), 0.1


def records_file(source: Path) -> Path | None:
    """The episode records of ``source``: itself if a .jsonl or .jsonl.gz file, its episodes.jsonl (or
    episodes.jsonl.gz) if a run folder, else None."""
    from avp_experiment.results import records_file as found

    path = found(source)
    return path if path.is_file() and path.name.endswith((".jsonl", ".jsonl.gz")) else None


def trace_from_run(out: Path, seed: int, method: str, mode: str, ego: int | None = None) -> tuple[dict, float]:
    """(trace summary, dt) of one record of an experiment folder or a .jsonl(.gz) file of records (of ego ``ego`` of
    a fleet: ``method`` its method or the fleet's label); ValueError naming what is missing."""
    from avp_experiment.results import open_records

    path = records_file(out)
    if path is None:
        raise ValueError(f"{out}: no episodes.jsonl (not an `avp experiment --out` folder)")
    found = None
    with open_records(path) as f:
        for line in f:
            if line.strip():
                r = json.loads(line)
                if ego is not None and (r.get("ego") != ego or method not in (r.get("method"), r.get("ego_method"))):
                    continue
                if r.get("seed") == seed and (ego is not None or r.get("method") == method) and r.get("mode") == mode:
                    found = r
    if found is None:
        raise ValueError(f"{path}: no episode of method {method!r}, seed {seed}, mode {mode!r}"
                         + (f", ego {ego}" if ego is not None else ""))
    if "decision_trace" not in found:
        raise ValueError(f"{path}: the {method} seed {seed} {mode} record has no decision_trace (recorded before "
                         "v0.3.0: run it again with avp experiment)")
    return found["decision_trace"], 0.1


def explain(source: str, seed: int | None = None, method: str = "bezier", mode: str = "reactive",
            ego: int | None = None) -> str:
    """The text ``avp why`` prints for a bag or a run folder (``ego``: one ego of several)."""
    p = Path(source)
    who = f", ego {ego}" if ego is not None else ""
    if records_file(p) is not None:
        if seed is None:
            raise ValueError("a run folder needs --seed (and --method, --mode)")
        summary, dt = trace_from_run(p, seed, method, mode, ego)
        head = f"{p}: {method} seed {seed} {mode}{who}"
    else:
        summary, dt = trace_from_bag(p, ego)
        head = f"{p}: the last episode of the bag{who}"
    return f"{head}\n{spells_text(summary, dt)}"


def cmd_why(args: argparse.Namespace) -> int:
    try:
        print(explain(args.source, args.seed, args.method, args.mode, args.ego))
    except (ValueError, OSError) as exc:
        print(f"[avp why] {exc}", file=sys.stderr)
        return 2
    return 0


def add_command(sub) -> None:
    """The ``avp why`` sub-command."""
    p = sub.add_parser("why", help="why the ego was not moving: an episode's idle spells and their causes")
    p.add_argument("source", help="a bag, the --out folder of avp experiment, or a .jsonl file of its records")
    p.add_argument("--seed", type=int, help="the episode of a run folder or records file")
    p.add_argument("--method", default="bezier")
    p.add_argument("--mode", default="reactive", choices=["reactive", "non_reactive"])
    p.add_argument("--ego", type=int, default=None, metavar="I", help="ego I of several (a bag of avp demo --egos K, "
                   "or a fleet's records; --method: its method or the fleet label)")
    p.set_defaults(func=cmd_why)
