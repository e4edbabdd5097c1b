"""The results folder of ``avp experiment`` (:mod:`.runner`): what the episodes depend on (``OUT/run.json``: run
config, intent weights, avp_sim values, method profile digests; a mismatch refuses the folder), the episode
records (``OUT/episodes.jsonl``: one fsync'ed JSON line each, a line cut by an interruption dropped) and the log
of invocations (``OUT/runs.jsonl``).

Committed records are compressed (``episodes.jsonl.gz``, ``gzip -9n``): :func:`records_file` finds a folder's
records under either name and :func:`open_records` reads either, so every reader (the summary, ``avp why``, the
tools) takes a compressed folder as it takes a plain one. The writer appends to the plain file only: the runner
refuses to add episodes to a folder holding only ``episodes.jsonl.gz`` (gunzip it first)."""

from __future__ import annotations

import argparse
import gzip
import hashlib
import json
import os
from collections.abc import Iterable
from dataclasses import asdict
from pathlib import Path
from typing import TextIO

from avp_episode.profiles import MethodProfile, load_profile
from avp_episode.run_config import Key, RunConfig, sim_values

LOCK_FILE = ".lock"
RESULTS_FILE = "episodes.jsonl"
RUN_FILE = "run.json"
RUNS_LOG = "runs.jsonl"
SEEDS_FILE = "seeds.json"  # which seeds build a scenario (avp_experiment.runner.valid_seeds caches them here)
GZ = ".gz"


def mode_name(reactive: bool) -> str:
    return "reactive" if reactive else "non_reactive"


def record_key(r: dict) -> Key:
    return (str(r["method"]), int(r["seed"]), str(r["mode"]))


def intent_identity(cfg: RunConfig) -> str:
    """Which intent weights the episodes use: 'sha256:<hex> (shipped)', 'sha256:<hex> (<path as given>)' or
    'random seed N' (no machine-specific path: summaries made on two machines compare)."""
    from avp_perception.core.pipeline import shipped_weights_path
    from avp_predictors.intent_model import weights_path

    path = weights_path(cfg.intent_weights) if cfg.intent_weights else shipped_weights_path()
    if path is None:
        return f"random seed {cfg.intent_seed}"
    if not path.is_file():
        raise ValueError(f"--intent-weights {path}: no such file")
    return f"sha256:{hashlib.sha256(path.read_bytes()).hexdigest()} ({cfg.intent_weights or 'shipped'})"


def check_method(profile: MethodProfile) -> str:
    """'' if the method can run in this build, else why not."""
    if not profile.available:
        return profile.unavailable_reason or "not available"
    from avp_predictors.prediction import make_predictor
    from avp_world.lot import load_bundled_lot

    try:
        make_predictor(profile.predictor, load_bundled_lot())
    except (ValueError, ImportError) as exc:
        return f"predictor {profile.predictor!r} is not in this build ({exc})"
    return ""


def profile_digest(profile: MethodProfile) -> str:
    """Hash of the profile file; for the learned predictor also of the trajectory weights it loads, and of the
    intent weights a profile names (``perception.intent_weights``), so that episodes of other weights are never
    mixed into one results folder."""
    h = hashlib.sha256(Path(profile.source).read_bytes())
    if profile.planner != load_profile(profile.source).planner:  # protocol / --planner-param values on top
        h.update(json.dumps(profile.planner, sort_keys=True).encode())
    if profile.predictor == "learned":
        from avp_predictors.learned_prediction import weights_path

        w = weights_path(str(profile.prediction.get("learned.weights", "")))
        h.update(w.read_bytes() if w.is_file() else b"random weights")
    if profile.intent_weights:
        from avp_predictors.intent_model import weights_path as intent_weights_path

        w = intent_weights_path(profile.intent_weights)
        if not w.is_file():
            raise ValueError(f"{profile.source}: field 'perception.intent_weights': {w}: no such file")
        h.update(w.read_bytes())
    return h.hexdigest()[:16]


def portable_path(path: str) -> str:
    """A lot file as run.json and the summary name it: relative to the clone when it lies in one (a results folder
    moves with the repository and must not name this machine's paths), else as given."""
    if not path or not Path(path).is_absolute():
        return path
    marker = "/src/avp_"  # a file of the clone's packages, wherever the clone was (also for run.json written before)
    i = path.rfind(marker)
    return path[i + 1:] if i >= 0 else path


def _portable_sim(d: dict) -> dict:
    return {**d, "lot_file": portable_path(d["lot_file"])} if isinstance(d, dict) and d.get("lot_file") else d


def run_identity(cfg: RunConfig, profiles: Iterable[MethodProfile]) -> dict:
    """What OUT/run.json must match: the run config, the intent weights, every avp_sim parameter value (so that
    a change of the shipped scenario defaults is not mixed with earlier episodes), the lot (name and file hash)
    and the method profiles; ``resolved``: every planner value each method runs with and, with noisy sensing, every
    tracker value (so that a change of the code's defaults is not mixed with earlier episodes either)."""
    from avp_episode.metrics import lot_record
    from avp_episode.profiles import planner_values
    from avp_episode.run_config import tracker_values
    from avp_sim.core.factory import load_lot_param

    sim = sim_values(cfg)
    config = asdict(cfg)
    config["sim_overrides"] = _portable_sim(config["sim_overrides"])
    profiles = list(profiles)
    resolved = {"planner": {p.name: planner_values(p) for p in profiles},
                "tracker": tracker_values(cfg) if sim["sensing.model"] != "exact" else {}}
    resolved = json.loads(json.dumps(resolved))  # as run.json holds them (tuples as lists)
    return {"config": config, "intent": intent_identity(cfg), "sim": _portable_sim(sim),
            "lot": lot_record(load_lot_param(sim["lot_file"])),
            "methods": {p.name: profile_digest(p) for p in profiles}, "resolved": resolved}


def _changed_values(old: dict | None, new: dict) -> list[str]:
    """The keys whose values differ between two resolved-value dicts (none when ``old`` was not recorded: a folder
    written before run.json held them)."""
    if not isinstance(old, dict):
        return []
    return sorted(k for k in set(old) | set(new) if old.get(k) != new.get(k))


def check_run_file(out: Path, ident: dict) -> dict:
    """Merge ``ident`` into OUT/run.json; ValueError if the folder holds results of other settings."""
    path = out / RUN_FILE
    if path.is_file():
        old = json.loads(path.read_text())
        if isinstance(old.get("config"), dict):  # fields added since (protocol, ...) read as their defaults
            old["config"] = {**asdict(RunConfig()), **old["config"]}
            old["config"]["sim_overrides"] = _portable_sim(old["config"]["sim_overrides"])
        old["sim"] = _portable_sim(old.get("sim"))
        if isinstance(old.get("sim"), dict):  # avp_sim parameters added since read as their defaults
            from avp_sim.params import SIM_PARAMS

            old["sim"] = {**{s.name: s.default for s in SIM_PARAMS if s.name not in old["sim"]}, **old["sim"]}
        if "lot" not in old:  # results made before records named their lot were made on the bundled paper lot
            from avp_episode.metrics import lot_record
            from avp_world.lot import load_bundled_lot

            old["lot"] = lot_record(load_bundled_lot())
        for k in ("sim", "lot", "intent", "config"):  # sim first: it names the parameters that differ
            if old.get(k) != ident[k]:
                if k == "sim" and isinstance(old.get(k), dict):
                    diff = sorted(n for n in set(old[k]) | set(ident[k]) if old[k].get(n) != ident[k].get(n))
                    what = f"other avp_sim parameters ({', '.join(diff)})"
                elif k == "sim":
                    what = "avp_sim parameters that were not recorded (an older run)"
                else:
                    what = f"{k} = {old.get(k)!r}, this command uses {ident[k]!r}"
                raise ValueError(f"{path}: the results there were made with {what}; use another --out "
                                 f"(or delete {out})")
        for name, digest in ident["methods"].items():
            if old.get("methods", {}).get(name, digest) != digest:
                raise ValueError(f"{path}: method profile {name!r} changed since its episodes there were run; "
                                 f"use another --out")
        before = old.get("resolved") or {}
        if isinstance(before.get("planner"), dict):  # planner parameters added since read as their shipped defaults
            from avp_episode.profiles import shipped_planner_values  # (a profile that set one changed its digest)

            shipped = json.loads(json.dumps(shipped_planner_values()))  # as run.json holds them
            before = {**before, "planner": {n: {**{k: v for k, v in shipped.items() if k not in vals}, **vals}
                                            if isinstance(vals, dict) and vals else vals
                                            for n, vals in before["planner"].items()}}
        for name, values in ident["resolved"]["planner"].items():
            changed = _changed_values(before.get("planner", {}).get(name), values)
            if changed:
                raise ValueError(f"{path}: method {name!r} ran there with other planner values ({', '.join(changed)})"
                                 "; a default changed since? use another --out")
        tracker_before = before.get("tracker") or None
        if isinstance(tracker_before, dict) and tracker_before:  # tracker parameters added since: their defaults
            from avp_episode.run_config import tracker_values

            tracker_before = {**{k: v for k, v in tracker_values(RunConfig()).items() if k not in tracker_before},
                              **tracker_before}
            before = {**before, "tracker": tracker_before}
        changed = _changed_values(tracker_before, ident["resolved"]["tracker"])
        if changed:
            raise ValueError(f"{path}: the tracker ran there with other values ({', '.join(changed)}); use another "
                             "--out")
        ident = {**old, "methods": {**old.get("methods", {}), **ident["methods"]},
                 "resolved": {"planner": {**before.get("planner", {}), **ident["resolved"]["planner"]},
                              "tracker": before.get("tracker") or ident["resolved"]["tracker"]}}
    out.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(ident, indent=2) + "\n")
    return ident


# ------------------------------------------------------------------------------------------ results file


def records_file(source: str | Path) -> Path:
    """The episode records of ``source``: a folder's ``episodes.jsonl``, else its ``episodes.jsonl.gz``; a file is
    itself, or ``X.jsonl.gz`` when ``X.jsonl`` is not there but that is. When neither is there, the plain name."""
    source = Path(source)
    plain = source / RESULTS_FILE if source.is_dir() else source
    packed = plain.with_name(plain.name + GZ)
    return packed if not plain.exists() and packed.is_file() else plain


def open_records(path: str | Path) -> TextIO:
    """A text stream of a file of JSON lines, plain (``.jsonl``) or gzip-compressed (``.jsonl.gz``); a folder reads
    as its :func:`records_file`."""
    path = records_file(path)
    if path.name.endswith(GZ):
        return gzip.open(path, "rt", encoding="utf-8")
    return path.open(encoding="utf-8")


def records_stem(path: str | Path) -> str:
    """A records file's name without ``.jsonl``/``.jsonl.gz`` (``episodes`` for both of a run folder's)."""
    name = Path(path).name.removesuffix(GZ)
    return name.removesuffix(".jsonl")


def read_results(path: Path) -> list[dict]:
    """Records of a JSONL file (or of a ``.jsonl.gz`` one, or of a folder's :func:`records_file`); a last line cut
    off by an interruption is removed from a plain file."""
    path = records_file(path)
    if not path.is_file():
        return []
    if path.name.endswith(GZ):  # committed records: read as they are
        with gzip.open(path, "rb") as f:
            data = f.read()
    else:
        data = path.read_bytes()
        if data and not data.endswith(b"\n"):  # an interrupted write: drop the partial line
            cut = data.rfind(b"\n") + 1
            with path.open("r+b") as f:
                f.truncate(cut)
            data = data[:cut]
    out = []
    for n, line in enumerate(data.decode().splitlines(), 1):
        if not line.strip():
            continue
        try:
            out.append(json.loads(line))
        except json.JSONDecodeError as exc:
            raise ValueError(f"{path}:{n}: not a JSON line ({exc})") from None
    return out


class ResultsWriter:
    """Appends records as JSON lines, each flushed and fsync'ed (an interruption loses at most one line)."""

    def __init__(self, path: Path):
        self.path = path
        self.f = path.open("a")

    def write(self, record: dict) -> None:
        self.f.write(json.dumps(record, sort_keys=True, allow_nan=False) + "\n")
        self.f.flush()
        os.fsync(self.f.fileno())

    def close(self) -> None:
        self.f.close()


def code_commit() -> str:
    """The checked-out commit of the code this process runs (read when the run starts)."""
    from avp_common.provenance import source_commit

    return source_commit(__file__)


def log_invocation(out: Path, args: argparse.Namespace, started: str, wall_s: float, ran: int, todo: int,
                   commit: str) -> None:
    """Append this invocation to ``OUT/runs.jsonl`` (see the module docstring)."""
    line = {"started": started, "wall_s": round(wall_s, 1), "episodes_run": ran, "episodes_todo": todo,
            "workers": args.workers, "transport": args.transport, "cpu_count": os.cpu_count(),
            "loadavg_end": [round(x, 2) for x in os.getloadavg()],
            "commit": commit,
            "options": {k: portable_path(v) if k == "lot" else v for k, v in sorted(vars(args).items())
                        if isinstance(v, (str, int, float, bool, list))}}
    with open(out / RUNS_LOG, "a") as f:
        f.write(json.dumps(line) + "\n")


def being_written(out: Path) -> bool:
    """Whether an ``avp experiment`` holds ``out``'s lock now (:func:`lock_folder`): its records are a run still
    going, not a cell's."""
    import fcntl

    try:
        f = open(out / LOCK_FILE)  # noqa: SIM115 - closed below
    except OSError:
        return False
    with f:
        try:
            fcntl.flock(f.fileno(), fcntl.LOCK_SH | fcntl.LOCK_NB)
        except BlockingIOError:
            return True
        fcntl.flock(f.fileno(), fcntl.LOCK_UN)
        return False


def lock_folder(out: Path):
    """Hold an exclusive lock on the results folder while this invocation writes it (released when the returned
    file is closed or the process ends); ValueError when another ``avp experiment`` holds it. Two invocations on one
    folder would each run the episodes the other is running and record them twice."""
    import fcntl

    out.mkdir(parents=True, exist_ok=True)
    f = open(out / LOCK_FILE, "a")  # noqa: SIM115 - held open: the lock lives as long as the file
    try:
        fcntl.flock(f.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        f.close()
        raise ValueError(f"{out}: another avp experiment is writing this folder; wait for it or use another --out") \
            from None
    return f
