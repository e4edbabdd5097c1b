"""Committed records are compressed (``episodes.jsonl.gz``): every reader takes a compressed folder or file as it
takes a plain one (avp_experiment.results.open_records / records_file), and the runner, which appends to the plain
file, refuses to add episodes to a folder holding only the compressed one."""

from __future__ import annotations

import argparse
import gzip
import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from avp_experiment.results import RESULTS_FILE, open_records, read_results, records_file, records_stem
from avp_experiment.runner import add_arguments, run_experiment
from avp_motion.trace import DecisionTrace

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tools"))

import compare_records  # noqa: E402
import fleet_pairs  # noqa: E402
import records_digest  # noqa: E402


def _gzip_folder(plain: Path, packed: Path) -> Path:
    """A copy of the run folder ``plain`` whose records are episodes.jsonl.gz (gzip -9n, as committed)."""
    shutil.copytree(plain, packed)
    data = (packed / RESULTS_FILE).read_bytes()
    (packed / (RESULTS_FILE + ".gz")).write_bytes(gzip.compress(data, compresslevel=9, mtime=0))
    (packed / RESULTS_FILE).unlink()
    return packed


def _argv(out: Path, *extra: str) -> list[str]:
    return ["--methods", "blind", "--scenarios", "1", "--mode", "non-reactive", "--t-final", "5", "--no-progress",
            "--out", str(out), *extra]


def _run(out: Path, *extra: str) -> dict:
    p = argparse.ArgumentParser()
    add_arguments(p)
    return run_experiment(p.parse_args(_argv(out, *extra)))


@pytest.fixture(scope="module")
def folders(tmp_path_factory) -> tuple[Path, Path]:
    """(a run folder of one short episode, its copy with the records compressed)."""
    base = tmp_path_factory.mktemp("records")
    _run(base / "plain")
    return base / "plain", _gzip_folder(base / "plain", base / "packed")


def test_records_file_finds_the_plain_or_the_compressed_records(tmp_path):
    assert records_file(tmp_path) == tmp_path / "episodes.jsonl"  # neither: the name the runner writes
    (tmp_path / "episodes.jsonl.gz").write_bytes(gzip.compress(b'{"a": 1}\n'))
    assert records_file(tmp_path) == tmp_path / "episodes.jsonl.gz"
    assert records_file(tmp_path / "episodes.jsonl") == tmp_path / "episodes.jsonl.gz"  # the old name still reads
    assert read_results(tmp_path / "episodes.jsonl.gz") == read_results(tmp_path) == [{"a": 1}]
    (tmp_path / "episodes.jsonl").write_text('{"a": 2}\n')  # gunzipped (-k) and resumed: the plain file is current
    assert records_file(tmp_path) == tmp_path / "episodes.jsonl" and read_results(tmp_path) == [{"a": 2}]
    with open_records(tmp_path / "episodes.jsonl.gz") as f:
        assert f.read() == '{"a": 1}\n'
    assert records_stem("x/arm.jsonl.gz") == records_stem("arm.jsonl") == "arm"


def test_a_compressed_folder_summarises_and_digests_as_the_plain_one(folders, tmp_path):
    plain, packed = folders
    assert read_results(records_file(packed)) == read_results(records_file(plain)) != []
    summary = (plain / "summary.md").read_text()
    (packed / "summary.md").unlink()
    (packed / "summary.json").unlink()
    assert _run(packed, "--summary-only")["ran"] == 0
    assert (packed / "summary.md").read_text() == summary
    assert json.loads((packed / "summary.json").read_text()) == json.loads((plain / "summary.json").read_text())
    assert not (packed / RESULTS_FILE).exists()  # read, not decompressed
    records_digest.write(plain, tmp_path / "plain.json")
    records_digest.write(packed, tmp_path / "packed.json")
    assert (tmp_path / "plain.json").read_text() == (tmp_path / "packed.json").read_text()
    status, lines = records_digest.check(packed, tmp_path / "plain.json")
    assert status == 0 and " 0 with another outcome" in lines[0]
    assert compare_records._records(str(packed)) == compare_records._records(str(plain))


def test_the_runner_does_not_append_to_a_compressed_folder(folders, tmp_path):
    _, packed = folders
    more = shutil.copytree(packed, tmp_path / "more")
    r = subprocess.run([sys.executable, "-m", "avp_bringup.cli", "experiment", *_argv(more, "--scenarios", "2")],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 2 and "gunzip" in r.stderr and str(more / "episodes.jsonl.gz") in r.stderr, r.stderr
    assert not (more / RESULTS_FILE).exists()


def test_avp_why_reads_a_compressed_folder_and_file(tmp_path):
    tr = DecisionTrace(0.1)
    for k in range(30):
        tr.add_step(k, "idle", "vehicle:braking", 1003)
    rec = {"method": "bezier", "seed": 5, "mode": "reactive", "decision_trace": tr.summary()}
    (tmp_path / "episodes.jsonl.gz").write_bytes(gzip.compress((json.dumps(rec) + "\n").encode()))
    for source in (tmp_path, tmp_path / "episodes.jsonl.gz"):
        r = subprocess.run([sys.executable, "-m", "avp_bringup.cli", "why", str(source), "--seed", "5"],
                           capture_output=True, text=True, timeout=60)
        assert r.returncode == 0, r.stderr
        assert f"{source}: bezier seed 5 reactive" in r.stdout and "blocking agent(s) [1003]" in r.stdout


def test_compare_records_keeps_every_ego_of_a_fleet_episode_apart(tmp_path, capsys):
    """A fleet writes a record per ego with the same (method, seed, mode): each is compared with its own ego's."""
    recs = [{"method": "fleet:bezier,bezier", "seed": 3, "mode": "reactive", "ego": i, "status": "success",
             "timings": {"decisions": i}} for i in range(2)]
    for name, last in (("a", "success"), ("b", "timeout")):
        (tmp_path / name).mkdir()
        rs = [dict(recs[0]), {**recs[1], "status": last}]
        (tmp_path / name / "episodes.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rs))
    assert len(compare_records._records(str(tmp_path / "a"))) == 2
    assert compare_records.main([str(tmp_path / "a"), str(tmp_path / "a")]) == 0
    assert compare_records.main([str(tmp_path / "a"), str(tmp_path / "b")]) == 1  # ego 1's record differs
    assert "2 episodes in both, 1 equal, 1 differ" in capsys.readouterr().out


def test_fleet_pairs_reads_a_suite_column_by_folder_and_skips_its_seed_cache(tmp_path):
    """`fleet_pairs.py --by-folder OUT/<column>/*` also matches the column's seeds.json (a suite's shared cache)."""
    col = tmp_path / "paper_k2"
    for arm in ("bezier", "blind"):
        (col / arm).mkdir(parents=True)
        rs = [{"method": f"fleet:{arm},{arm}", "seed": 3, "mode": "reactive", "ego": i, "success": True,
               "spots_lost_to_ego": 0} for i in range(2)]
        (col / arm / "episodes.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rs))
    (col / "seeds.json").write_text(json.dumps({"3": True}))
    eps = fleet_pairs.episodes(sorted(col.iterdir()), {}, by_folder=True)
    assert sorted(eps) == ["bezier", "blind"] and [len(v[3]) for v in eps.values()] == [2, 2]
