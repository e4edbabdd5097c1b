"""Every process a graph starts ends with its starter, however the starter ends (avp_common.lifetime;
docs/architecture.md, "Processes"): real processes, found by pid, real DDS."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from avp_common.lifetime import ENV_PDEATHSIG, ENV_PID, alive, start_time, tie_env, untie_env

CLI = [sys.executable, "-m", "avp_bringup.cli"]
#: a child that ties itself to its starter as a node process does, then sleeps
TIED_CHILD = ("import time; from avp_common.lifetime import end_with_starter; end_with_starter(); print('tied', "
              "flush=True); time.sleep(600)")


def _wait_gone(pids, timeout: float) -> list[int]:
    """The pids of ``pids`` still running after up to ``timeout`` s (zombies count as gone)."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        left = [p for p in pids if alive(p)]
        if not left:
            return []
        time.sleep(0.1)
    return [p for p in pids if alive(p)]


def _children(pid: int) -> list[int]:
    """The child pids of process ``pid`` (Linux /proc)."""
    out: list[int] = []
    for task in Path(f"/proc/{pid}/task").iterdir():
        out += [int(c) for c in (task / "children").read_text().split()]
    return out


def _kill_all(pids) -> None:
    for p in pids:
        try:
            os.kill(p, signal.SIGKILL)
        except ProcessLookupError:
            pass


def test_a_tied_child_ends_when_its_killed_starter_ends(tmp_path):
    """A starter killed with SIGKILL (nothing of it runs afterwards): its tied child gets SIGTERM from the kernel and
    is gone within 2 s; a child given untie_env's environment lives on."""
    starter_code = (f"import subprocess, sys, time; from avp_common.lifetime import tie_env, untie_env\n"
                    f"a = subprocess.Popen([sys.executable, '-c', {TIED_CHILD!r}], env=tie_env(), "
                    f"stdout=subprocess.PIPE, start_new_session=True)\n"
                    f"b = subprocess.Popen([sys.executable, '-c', {TIED_CHILD!r}], env=untie_env(), "
                    f"stdout=subprocess.PIPE, start_new_session=True)\n"
                    f"a.stdout.readline(); b.stdout.readline(); print(a.pid, b.pid, flush=True); time.sleep(600)")
    starter = subprocess.Popen([sys.executable, "-c", starter_code], stdout=subprocess.PIPE, text=True)
    tied = untied = None
    try:
        tied, untied = map(int, starter.stdout.readline().split())
        assert alive(tied) and alive(untied)
        starter.kill()
        starter.wait(10)
        assert _wait_gone([tied], 5.0) == [], "the tied child outlived its killed starter"
        time.sleep(0.5)
        assert alive(untied), "the untied child ended with the starter"
    finally:
        starter.kill()
        _kill_all([p for p in (tied, untied) if p])


def test_a_child_tied_to_another_process_ends_with_it_not_with_its_parent():
    """tie_env(pid=...) of a process that is not the child's parent (what `avp swap-planner` gives a planner: the
    graph's launcher): the child outlives its parent, and ends once that process ends (the pidfd watcher)."""
    other = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(600)"])
    env = tie_env(pid=other.pid)
    assert env[ENV_PID] == str(other.pid) and env[ENV_PDEATHSIG] == "0"
    child = subprocess.Popen([sys.executable, "-c", TIED_CHILD], env=env, stdout=subprocess.PIPE,
                             start_new_session=True)
    try:
        assert child.stdout.readline().strip() == b"tied"
        time.sleep(0.5)
        assert child.poll() is None, "the child ended while the process it is tied to runs"
        other.kill()
        other.wait(10)
        child.wait(5)  # raises TimeoutExpired if it outlived it
        assert child.returncode in (-signal.SIGTERM, 143, 0)
    finally:
        other.kill()
        child.kill()


def test_a_child_whose_starter_ended_before_it_tied_itself_ends_at_once():
    """The race the prctl alone leaves open: the starter is gone before the child's start-up ties it."""
    sleeper = subprocess.Popen([sys.executable, "-c", "pass"])
    sleeper.wait(10)
    env = {**untie_env(), ENV_PID: str(sleeper.pid), "AVP_END_WITH_START": start_time(os.getpid()) or "1"}
    child = subprocess.run([sys.executable, "-c", TIED_CHILD], env=env, capture_output=True, timeout=30)
    assert child.returncode == 143 and b"tied" not in child.stdout


def test_alive_tells_a_pid_used_again_by_its_start_time():
    me = os.getpid()
    assert alive(me) and alive(me, start_time(me))
    assert not alive(me, "1")  # another start time: another process that had this pid


def _launch(env, tmp_path, *extra) -> tuple[subprocess.Popen, dict[str, int]]:
    """`avp launch` (its own session, as a terminal's job is) and the pids it printed, once every node started."""
    proc = subprocess.Popen([*CLI, "launch", "--log-dir", str(tmp_path / "logs"), *extra], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, start_new_session=True)
    pids: dict[str, int] = {}
    lines = []
    t0 = time.monotonic()
    while time.monotonic() - t0 < 120:
        line = proc.stdout.readline()
        if not line:
            break
        lines.append(line)
        if ": pid " in line:
            name, rest = line.split("[avp]", 1)[1].split(": pid ", 1)
            pids[name.strip()] = int(rest.split()[0])
        if "Ctrl-C stops the graph" in line:
            return proc, pids
    proc.kill()
    raise AssertionError("avp launch did not start its graph:\n" + "".join(lines))


def _graph_steps(env, n: int = 5, timeout: float = 90.0) -> bool:
    """Whether the domain's simulator publishes ``n`` ground-truth steps within ``timeout`` s (every node of the
    graph is up: the simulator's step 0 waits for all of them)."""
    code = ("import sys, time, rclpy\nfrom avp_msgs.msg import GroundTruth\nfrom avp_common.qos import GROUND_TRUTH\n"
            "rclpy.init(); node = rclpy.create_node('lifetime_probe'); seen = []\n"
            "node.create_subscription(GroundTruth, '/avp/debug/ground_truth', lambda m: seen.append(m.step),\n"
            "                         GROUND_TRUTH)\n"
            f"t0 = time.monotonic()\nwhile len(seen) < {n} and time.monotonic() - t0 < {timeout}:\n"
            "    rclpy.spin_once(node, timeout_sec=0.1)\n"
            f"sys.exit(0 if len(seen) >= {n} else 1)")
    return subprocess.run([sys.executable, "-c", code], env=env, timeout=timeout + 30).returncode == 0


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP, signal.SIGKILL],
                         ids=lambda s: signal.Signals(s).name)
def test_no_node_outlives_avp_launch_whatever_the_signal(ros_env, tmp_path, sig):
    """`avp launch` ended with each signal: every node process it started (by pid) is gone within a few seconds;
    SIGHUP (the terminal closed) is a clean stop as SIGTERM is."""
    proc, pids = _launch(ros_env, tmp_path, "--ego", "scripted")
    try:
        assert len(pids) == 3, pids  # simulator, scripted driver, scene node
        assert _graph_steps(ros_env), "the graph did not run"
        proc.send_signal(sig)
        out = proc.communicate(timeout=60)[0]
        left = _wait_gone(list(pids.values()), 10.0)
        assert left == [], f"{signal.Signals(sig).name}: node processes left {left}"
        if sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
            assert proc.returncode == 0 and "graph stopped" in out, out
    finally:
        proc.kill()
        _kill_all(pids.values())


def _swap(env, tmp_path, timeout: float = 180.0) -> tuple[int, str]:
    """`avp swap-planner cautious` into the domain's graph: (its exit status, its output)."""
    res = subprocess.run([*CLI, "swap-planner", "cautious", "--log-dir", str(tmp_path / "swap")], env=env,
                         capture_output=True, text=True, timeout=timeout, start_new_session=True)
    return res.returncode, res.stdout + res.stderr


def test_a_swapped_planner_lives_as_long_as_the_graph_it_joined(ros_env, tmp_path):
    """A planner started by `avp swap-planner` outlives the swap command (which has ended) and ends within seconds
    of the graph's launcher being killed (SIGKILL: no clean stop shut it down)."""
    import re

    proc, pids = _launch(ros_env, tmp_path)
    swapped: list[int] = []
    try:
        assert _graph_steps(ros_env), "the graph did not run"
        rc, out = _swap(ros_env, tmp_path)
        assert rc == 0, out
        swapped = [int(p) for p in re.findall(r"\(pid (\d+),", out)]
        assert len(swapped) == 1, out
        time.sleep(2.0)
        assert alive(swapped[0]), "the swapped-in planner ended with the swap command"
        proc.kill()
        proc.wait(10)
        left = _wait_gone([*pids.values(), *swapped], 10.0)
        assert left == [], f"processes left after the launcher's SIGKILL: {left} (swapped: {swapped})"
    finally:
        proc.kill()
        _kill_all([*pids.values(), *swapped])


def test_a_killed_demos_bag_stays_readable_and_the_next_launch_starts(ros_env, tmp_path):
    """`avp demo` killed with SIGKILL mid-episode: its node processes (its children, by pid) are gone within
    seconds; the bag it was recording reads up to its last complete split (the rosbags reader); `avp launch`
    afterwards starts its graph, which runs."""
    from rosbags.highlevel import AnyReader

    from avp_bag.typestore import make_typestore

    bag = tmp_path / "bag"
    demo = subprocess.Popen([*CLI, "demo", "--seed", "1", "--no-gif", "--out", str(tmp_path / "demo"), "--bag",
                             str(bag)], env=ros_env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            start_new_session=True)
    children: list[int] = []
    try:
        t0 = time.monotonic()  # the episode has run a while: several of the recorder's 1 s splits are complete
        while time.monotonic() - t0 < 180 and len(list(bag.glob("*.mcap"))) < 4:
            assert demo.poll() is None, demo.communicate()[0]
            time.sleep(0.2)
        children = _children(demo.pid)
        assert len(children) >= 5, children  # simulator, belief, prediction, planner, scene
        demo.kill()
        demo.wait(10)
        assert _wait_gone(children, 10.0) == [], "node processes outlived the killed demo"
        with AnyReader([bag], default_typestore=make_typestore()) as reader:
            n = sum(1 for _ in reader.messages())
        assert n > 0
    finally:
        demo.kill()
        _kill_all(children)
    proc, pids = _launch(ros_env, tmp_path, "--ego", "scripted")
    try:
        assert _graph_steps(ros_env), "avp launch after the killed demo did not run"
        proc.send_signal(signal.SIGINT)
        assert proc.wait(60) == 0
    finally:
        proc.kill()
        _kill_all(pids.values())
