"""``avp experiment`` ended by a signal mid-run: SIGTERM (a scheduler's) ends its workers at once and exits 143,
SIGKILL (the OOM killer's) leaves no worker behind either, and the same command then finishes the run with every
episode recorded once."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow


def _cmd(out: Path) -> list[str]:
    return [sys.executable, "-m", "avp_bringup.cli", "experiment", "--methods", "blind", "--scenarios", "3", "--mode",
            "non-reactive", "--workers", "2", "--no-progress", "--out", str(out)]


def _alive(pid: int) -> bool:
    """The process exists and is not a zombie."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except (OSError, IndexError):
        return False


def _workers(parent: int) -> list[int]:
    """Pids of ``parent``'s pool workers (spawned processes; not the resource tracker)."""
    pids = []
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            ppid = int((d / "stat").read_text().rsplit(")", 1)[1].split()[1])
            spawned = b"spawn_main" in (d / "cmdline").read_bytes()
        except (OSError, IndexError, ValueError):
            continue
        if ppid == parent and spawned:
            pids.append(int(d.name))
    return pids


def _run_until_recording(out: Path) -> tuple[subprocess.Popen, list[int]]:
    """The command started; returns once its first episode is recorded, with its two workers in the next ones."""
    proc = subprocess.Popen(_cmd(out), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    records, t0 = out / "episodes.jsonl", time.monotonic()
    while not (records.is_file() and records.read_text().count("\n") >= 1):
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() - t0 < 300, "no episode recorded after 300 s"
        time.sleep(0.2)
    workers = _workers(proc.pid)
    assert len(workers) == 2, workers
    return proc, workers


def _wait_gone(pids: list[int], limit: float = 60.0) -> list[int]:
    """Those of ``pids`` still alive after ``limit`` s (then killed, so that a failing test leaves none)."""
    t0 = time.monotonic()
    while any(_alive(p) for p in pids) and time.monotonic() - t0 < limit:
        time.sleep(0.2)
    left = [p for p in pids if _alive(p)]
    for p in left:
        os.kill(p, signal.SIGKILL)
    return left


def _keys(out: Path) -> list[tuple]:
    return [(r["method"], r["seed"], r["mode"]) for r in
            (json.loads(line) for line in (out / "episodes.jsonl").read_text().splitlines())]


def test_sigterm_ends_the_workers_and_the_same_command_finishes_the_run(tmp_path):
    out = tmp_path / "run"
    proc, workers = _run_until_recording(out)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 143, err
    assert "terminated; the finished episodes are in" in err and "run the same command to continue" in err, err
    assert _wait_gone(workers) == []  # ended now, not after their episodes
    done = _keys(out)
    assert 1 <= len(done) < 3, done
    r = subprocess.run(_cmd(out), capture_output=True, text=True, timeout=600)
    assert r.returncode == 0 and f"{len(done)} already in" in r.stdout, r.stdout + r.stderr
    keys = _keys(out)
    assert len(keys) == 3 and len(set(keys)) == 3, keys


def test_a_killed_run_leaves_no_worker_behind(tmp_path):
    """Without ``PR_SET_PDEATHSIG`` the workers would finish their episodes and then wait for work forever."""
    proc, workers = _run_until_recording(tmp_path / "run")
    os.kill(proc.pid, signal.SIGKILL)
    proc.communicate(timeout=60)
    assert _wait_gone(workers) == []
