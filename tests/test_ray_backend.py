"""``avp experiment --backend ray`` on a real local Ray cluster: a head and a worker node started by the
test with ``ray start`` as separate processes on loopback. The records equal the local backend's (timing fields
aside); a worker process killed mid-episode costs a retry, never a lost or doubled record; a driver killed
mid-sweep is finished by the same command."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

from avp_episode.metrics import comparable
from avp_experiment.ray_backend import LocalRayCluster
from avp_experiment.runner import RESULTS_FILE, main, read_results, record_key

ray = pytest.importorskip("ray", reason="make setup installs Ray (requirements-ray.txt) unless AVP_WITH_RAY=0")

COMMON = ["--seed-base", "1", "--methods", "bezier,nawaz", "--no-progress"]


@pytest.fixture(scope="module")
def cluster():
    """A two-node Ray cluster on loopback: the head and one worker node, 1 CPU each, in a temp dir of their own.
    The worker node's first ``ray start`` fails (a ``ray`` first on the cluster's PATH exits 1 once, as Ray's own
    does when the raylet misses its 30 s to register on a loaded machine); the cluster starts it again, with the
    three real tries a user's cluster has."""
    tmp = tempfile.mkdtemp(prefix="avpray", dir="/tmp")  # short: Ray's socket paths must fit in 107 bytes
    try:
        wrapper = Path(tmp) / "bin" / "ray"
        wrapper.parent.mkdir()
        wrapper.write_text(f"#!/bin/sh\ncase \"$*\" in *--address*) [ -e {tmp}/failed ] || "
                           f"{{ touch {tmp}/failed; echo 'first start fails' >&2; exit 1; }};; esac\n"
                           f"exec {shutil.which('ray')} \"$@\"\n")
        wrapper.chmod(0o755)
        c = LocalRayCluster(tmp, cpus=(1, 1))
        c.env["PATH"] = f"{wrapper.parent}:{c.env['PATH']}"
        try:
            yield c.start(attempts=4)
        finally:
            c.stop()
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def test_a_worker_node_whose_start_fails_is_started_again(cluster):
    """The fixture's worker node failed its first ``ray start`` and came up on a later one: two CPUs in all. (Under
    make test's load a real start can miss Ray's 30 s too: one fresh clone's node came up on attempt 3.)"""
    log = (Path(cluster.temp_dir) / "node1.log").read_text()
    assert "first start fails" in log and "attempt 2" in log, log[-2000:]
    assert "Ray runtime started." in log.split("attempt ")[-1], log[-2000:]
    assert cluster.cluster_cpus() == 2.0


def _records(out: Path) -> dict:
    return {record_key(r): comparable(r) for r in read_results(out / RESULTS_FILE)}


def _driver(out: Path, cluster: LocalRayCluster, *extra: str) -> subprocess.Popen:
    """``avp experiment --backend ray`` on ``cluster`` in a process of its own (with the cluster's token)."""
    return subprocess.Popen([sys.executable, "-m", "avp_bringup.cli", "experiment", "--backend", "ray", "--address",
                             cluster.address, "--out", str(out), *COMMON, *extra],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=cluster.env)


def _episode_workers() -> list[int]:
    """Pids of Ray worker processes running an episode now (Ray titles a busy worker ``ray::<task name>``)."""
    pids = []
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                if (d / "cmdline").read_bytes().startswith(b"ray::_episode_task"):
                    pids.append(int(d.name))
            except OSError:
                continue
    return pids


@pytest.fixture(scope="module")
def local_records(tmp_path_factory):
    """The local backend's records of the episodes the Ray tests run (3 seeds x 2 methods x 2 modes, t_f 30 s)."""
    out = tmp_path_factory.mktemp("local")
    assert main(["--out", str(out), *COMMON, "--scenarios", "3", "--t-final", "30", "--workers", "0"]) == 0
    return _records(out)


def test_ray_records_equal_the_local_backends(cluster, local_records, tmp_path):
    out = tmp_path / "ray"
    p = _driver(out, cluster, "--scenarios", "3", "--t-final", "30")
    log, _ = p.communicate(timeout=600)
    assert p.returncode == 0, log
    assert _records(out) == local_records and len(local_records) == 12
    raw = read_results(out / RESULTS_FILE)
    assert len(raw) == 12  # each key once
    runs = [json.loads(line) for line in (out / "runs.jsonl").read_text().splitlines()]
    assert runs[-1]["options"]["backend"] == "ray" and runs[-1]["options"]["address"] == cluster.address


def test_a_worker_killed_mid_episode_is_retried_once_and_recorded_once(cluster, local_records, tmp_path):
    out = tmp_path / "ray"
    p = _driver(out, cluster, "--scenarios", "3", "--t-final", "30")
    killed = None
    deadline = time.monotonic() + 300
    while killed is None and p.poll() is None and time.monotonic() < deadline:
        busy = _episode_workers()
        if busy:
            killed = busy[0]
            os.kill(killed, signal.SIGKILL)
        time.sleep(0.02)
    log, _ = p.communicate(timeout=600)
    assert killed is not None, "no episode task seen running: nothing was killed\n" + log
    assert p.returncode == 0, log
    raw = read_results(out / RESULTS_FILE)
    assert sorted(record_key(r) for r in raw) == sorted(local_records)  # all 12 keys, none twice
    assert _records(out) == local_records  # the retried episode is the same episode


def test_a_driver_killed_mid_sweep_is_finished_by_the_same_command(cluster, local_records, tmp_path):
    out = tmp_path / "ray"
    p = _driver(out, cluster, "--scenarios", "3", "--t-final", "30")
    results = out / RESULTS_FILE
    deadline = time.monotonic() + 300
    while p.poll() is None and time.monotonic() < deadline:
        if results.exists() and len(read_results(results)) >= 2:
            p.kill()
            break
        time.sleep(0.05)
    p.communicate(timeout=60)
    first = len(read_results(results))
    assert 2 <= first < 12, f"the driver was not killed mid-sweep ({first} records)"
    again = _driver(out, cluster, "--scenarios", "3", "--t-final", "30")
    log, _ = again.communicate(timeout=600)
    assert again.returncode == 0, log
    assert f"{first} already in" in log
    raw = read_results(results)
    assert len(raw) == 12 and _records(out) == local_records


def test_without_ray_the_command_says_how_to_install_it(tmp_path, monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "ray", None)  # what `import ray` meets where Ray is not installed
    assert main(["--out", str(tmp_path / "x"), *COMMON, "--scenarios", "1", "--backend", "ray"]) == 2
    err = capsys.readouterr().err
    assert "pip install -r requirements-ray.txt" in err and not (tmp_path / "x").exists()
