"""``avp experiment --backend ray``: the episodes of a sweep as Ray tasks on a cluster.

One task per episode (``(method, seed, mode)``); each runs :func:`~.episodes.run_episode_inproc` in a Ray worker
process exactly as a ``--backend local`` worker does (one torch thread, the planner's wall-clock caps lifted), so
the records are the local backend's, timing fields aside. Results stream back to the driver as the tasks finish
and go through the same ``on_record`` as the local backend's: appended to ``OUT/episodes.jsonl`` and flushed,
so a driver killed mid-sweep loses nothing recorded and the same command runs the rest.

Faults: a task whose worker process dies (killed, out of memory, its node lost) is re-run once by Ray
(``max_retries=1``); the driver records a key once however often its task ran, and only when it returns. An
episode that raises is reported and left out, as with the local backend (never retried: it would raise again).

The cluster: ``--address HOST:PORT`` (or ``auto``: the one ``ray start`` made on this machine) joins a running
cluster whose nodes were started in a shell that sourced ``tools/env.sh`` (the workers import the workspace's
packages from their environment); without ``--address`` a private one-machine Ray instance with ``--workers``
CPUs is started and stopped with the run. docs/experiment.md "On a Ray cluster".
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from typing import Any

from avp_episode.run_config import Key, RunConfig

RAY_REQUIREMENT = "ray==2.60.0"
INSTALL_HINT = (f"--backend ray needs Ray: pip install -r requirements-ray.txt (it pins {RAY_REQUIREMENT}; "
                "make setup installs it unless AVP_WITH_RAY=0)")
#: Tasks in flight per cluster CPU: enough to keep every worker busy while results stream back, few enough that a
#: sweep of 10^5 episodes does not sit in the cluster's task table at once.
IN_FLIGHT_PER_CPU = 4


def import_ray():
    """The ``ray`` module, or a RuntimeError saying how to install it."""
    try:
        import ray
    except ImportError:
        raise RuntimeError(INSTALL_HINT) from None
    return ray


def _episode_task(key: Key, cfg: RunConfig, sources: dict[str, str]) -> dict:
    """The body of one Ray task (:func:`~.episodes.episode_in_worker`)."""
    from avp_episode.episodes import episode_in_worker

    return episode_in_worker(key, cfg, sources)


def connect(address: str | None, workers: int) -> tuple[Any, bool]:
    """``ray.init`` on ``address`` (None: a private local instance with ``workers`` CPUs); returns (ray, whether
    this call started the instance). A cluster that cannot be reached is a RuntimeError naming the address."""
    ray = import_ray()
    if ray.is_initialized():
        return ray, False
    kw: dict[str, Any] = {"logging_level": "WARNING", "log_to_driver": True}
    try:
        if address:
            ray.init(address=address, **kw)
        else:
            ray.init(num_cpus=max(1, workers), include_dashboard=False, **kw)
    except ConnectionError as exc:
        raise RuntimeError(f"--address {address}: no Ray cluster there ({exc})") from None
    return ray, True


def run_ray(keys: list[Key], cfg: RunConfig, on_record: Callable[[dict], None], address: str | None,
            workers: int, sources: dict[str, str] | None = None) -> list[str]:
    """Run ``keys`` as Ray tasks, calling ``on_record`` once per key as its task returns; returns the error lines of
    episodes that raised (left out of the results, as :func:`~.runner.run_inproc` does)."""
    ray, started = connect(address, workers)
    errors: list[str] = []
    pending: dict[Any, Key] = {}  # task -> its episode
    try:
        task = ray.remote(num_cpus=1, max_retries=1, retry_exceptions=False)(_episode_task)
        cpus = max(1, int(ray.cluster_resources().get("CPU", 1)))
        cfg_ref = ray.put(cfg)
        todo, recorded = list(reversed(keys)), set()
        while todo or pending:
            while todo and len(pending) < IN_FLIGHT_PER_CPU * cpus:
                key = todo.pop()
                pending[task.remote(key, cfg_ref, dict(sources or {}))] = key
            done, _ = ray.wait(list(pending), num_returns=1)
            for ref in done:
                key = pending.pop(ref)
                try:
                    record = ray.get(ref)
                except Exception as exc:  # noqa: BLE001 - one episode's failure must not stop the sweep
                    cause = getattr(exc, "cause", None) or exc
                    line = f"episode {key[0]} seed {key[1]} {key[2]} raised {type(cause).__name__}: {cause}"
                    errors.append(line)
                    print(f"[avp experiment] {line}", file=sys.stderr, flush=True)
                    continue
                if key not in recorded:  # a key is recorded once, however often Ray ran its task
                    recorded.add(key)
                    on_record(record)
    except BaseException:  # Ctrl-C or a lost cluster: what was recorded stays; the same command runs the rest
        for ref in pending:
            ray.cancel(ref, force=True)
        raise
    finally:
        if started:
            ray.shutdown()
    return errors


class LocalRayCluster:
    """A Ray cluster of separate ``ray start --block`` processes on loopback: a head and ``len(cpus) - 1`` worker
    nodes, ``cpus[i]`` CPUs each, under ``temp_dir`` (keep it short: Ray's socket paths must fit in 107 bytes).
    Each node runs in a process group of its own and :meth:`stop` ends exactly those (``ray stop`` would end every
    Ray process of the machine). The cluster takes Ray's token authentication with a fresh token of its own: a
    driver runs with :attr:`env` (``RAY_AUTH_MODE=token``, ``RAY_AUTH_TOKEN``), and ``~/.ray`` is not touched. For
    tests and benchmarks; a real cluster is started by hand (docs/experiment.md)."""

    def __init__(self, temp_dir: str, cpus: tuple[int, ...] = (1, 1), object_store_mb: int = 80) -> None:
        import os
        import secrets
        import socket

        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            self.port = s.getsockname()[1]
        self.address = f"127.0.0.1:{self.port}"
        self.temp_dir, self.cpus, self.object_store_mb = temp_dir, cpus, object_store_mb
        self.procs: list = []
        self.env = {**os.environ, "RAY_AUTH_MODE": "token", "RAY_AUTH_TOKEN": secrets.token_hex(32)}

    def _node(self, i: int, args: list[str], attempt: int = 1):
        import subprocess

        log = open(f"{self.temp_dir}/node{i}.log", "a")  # noqa: SIM115 - the node's own output, open while it runs
        log.write(f"# ray start of node {i}, attempt {attempt}\n")
        log.flush()
        return subprocess.Popen(["ray", "start", "--block", "--node-ip-address", "127.0.0.1", "--num-cpus",
                                 str(self.cpus[i]), "--object-store-memory", str(self.object_store_mb << 20),
                                 "--disable-usage-stats", "--temp-dir", f"{self.temp_dir}/node{i}", *args],
                                stdout=log, stderr=subprocess.STDOUT, start_new_session=True, env=self.env)

    def cluster_cpus(self) -> float:
        """The cluster's CPU count as a fresh driver sees it (0 while it is not up)."""
        import subprocess

        code = f"import ray; ray.init(address={self.address!r}, logging_level='ERROR'); " \
               "print(ray.cluster_resources().get('CPU', 0))"
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, env=self.env)
        try:
            return float(out.stdout.strip().splitlines()[-1])
        except (ValueError, IndexError):
            return 0.0

    def start(self, timeout: float = 300.0, attempts: int = 3) -> LocalRayCluster:
        """Start the nodes one after another, each when the one before counts its CPUs. A node whose ``ray start``
        exits before it registers is started again, up to ``attempts`` times in all: Ray gives a raylet a fixed 30 s
        to register with the head, which a machine under load (CI: four test processes on two cores) can miss."""
        import time
        from pathlib import Path

        Path(self.temp_dir).mkdir(parents=True, exist_ok=True)
        deadline = time.monotonic() + timeout
        for i in range(len(self.cpus)):
            head = ["--head", "--port", str(self.port), "--include-dashboard=false"]
            args = head if i == 0 else ["--address", self.address]
            self.procs.append(self._node(i, args))
            tries = 1
            while self.cluster_cpus() < sum(self.cpus[:i + 1]):
                exited = self.procs[i].poll() is not None
                if exited and tries < attempts and time.monotonic() < deadline:
                    self._end(self.procs[i])  # what the failed start left in its process group
                    tries += 1
                    self.procs[i] = self._node(i, args, tries)
                elif exited or time.monotonic() > deadline:
                    self.stop()
                    log = Path(f"{self.temp_dir}/node{i}.log").read_text()[-2000:]
                    raise RuntimeError(f"Ray node {i} did not come up on {self.address} in {tries} tries:\n{log}")
                time.sleep(1.0)
        return self

    def stop(self) -> None:
        for proc in reversed(self.procs):
            self._end(proc)
        self.procs = []

    @staticmethod
    def _end(proc) -> None:
        """End a node's process group: SIGTERM, then SIGKILL if it is still there after 10 s."""
        import os
        import signal
        import subprocess

        for sig, wait in ((signal.SIGTERM, 10.0), (signal.SIGKILL, 5.0)):
            try:
                os.killpg(proc.pid, sig)
                proc.wait(wait)
                return
            except ProcessLookupError:
                return
            except subprocess.TimeoutExpired:
                continue

    def __enter__(self) -> LocalRayCluster:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()
