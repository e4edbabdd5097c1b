"""Processes that end with the process that started them, however it ended (docs/architecture.md, "Processes").

A starter (``avp launch``, ``avp demo``, ``avp experiment``, a pool) gives each child the environment of
:func:`tie_env`; the child calls :func:`end_with_starter` at start-up. From then on the child gets SIGTERM — its
clean stop — within about a second of the starter's end, whether the starter returned, raised, was interrupted
or was killed with SIGKILL:

* Linux, where the starter is the child's parent and started it from its main thread: ``PR_SET_PDEATHSIG``
  (the kernel sends the signal when the parent ends; set in the child, so that no ``preexec_fn`` runs in a
  threaded starter);
* everywhere, and for a starter that is not the parent (a planner that ``avp swap-planner`` starts for a graph
  of another launcher): a watcher thread that waits on a pidfd of the starter (Linux) or polls its pid and start
  time every 0.2 s (elsewhere, and against a pid used again).

A child that has not ended :data:`GRACE_S` seconds after the signal is ended with ``os._exit``. ROS-free.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
import time
from collections.abc import Callable

#: the environment of a tied child: the pid of the process it ends with, that process's start time (against a pid
#: used again), and "1" where that process is its parent and started it from its main thread (PR_SET_PDEATHSIG)
ENV_PID = "AVP_END_WITH_PID"
ENV_START = "AVP_END_WITH_START"
ENV_PDEATHSIG = "AVP_END_WITH_PDEATHSIG"
#: seconds a child gets to stop cleanly once its starter has ended, before it is ended with os._exit
GRACE_S = 1.5
POLL_S = 0.2
_PR_SET_PDEATHSIG = 1


def start_time(pid: int) -> str:
    """The start time of process ``pid`` in clock ticks since boot (field 22 of /proc/<pid>/stat), "" where there is
    no /proc or no such process."""
    try:
        with open(f"/proc/{int(pid)}/stat", "rb") as f:
            stat = f.read().decode(errors="replace")
    except OSError:
        return ""
    return stat.rsplit(")", 1)[-1].split()[19]  # fields after the command name, which may hold spaces


def tie_env(env: dict | None = None, pid: int | None = None) -> dict:
    """A copy of ``env`` (default: this process's) for a child that is to end with process ``pid`` (default: this
    one, the child's parent)."""
    out = dict(os.environ if env is None else env)
    own = pid is None or int(pid) == os.getpid()
    pid = os.getpid() if pid is None else int(pid)
    out[ENV_PID] = str(pid)
    out[ENV_START] = start_time(pid)
    out[ENV_PDEATHSIG] = "1" if own and threading.current_thread() is threading.main_thread() else "0"
    return out


def untie_env(env: dict | None = None) -> dict:
    """A copy of ``env`` without the variables of :func:`tie_env`: a child that outlives its starter."""
    return {k: v for k, v in (os.environ if env is None else env).items()
            if k not in (ENV_PID, ENV_START, ENV_PDEATHSIG)}


def alive(pid: int, start: str = "") -> bool:
    """Whether process ``pid`` runs (a zombie does not), and is the one that started at ``start`` where given."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        pass  # it exists, another user's
    now = start_time(pid)
    if start and now and now != start:
        return False
    try:
        with open(f"/proc/{int(pid)}/stat", "rb") as f:
            state = f.read().decode(errors="replace").rsplit(")", 1)[-1].split()[0]
        return state not in ("Z", "X")
    except (OSError, IndexError):
        return True


def end_with_starter(on_end: Callable[[], None] | None = None) -> int | None:
    """Tie this process to the one named by :func:`tie_env`'s environment (nothing when it names none); returns its
    pid or None. ``on_end``: what to do when it ends (default: SIGTERM to this process, then ``os._exit(143)`` after
    :data:`GRACE_S` s if it is still here)."""
    raw = os.environ.get(ENV_PID, "")
    if not raw.isdigit():
        return None
    pid = int(raw)
    end_with_process(pid, os.environ.get(ENV_START, ""), pdeathsig=os.environ.get(ENV_PDEATHSIG) == "1",
                     on_end=on_end)
    return pid


def end_with_process(pid: int, start: str = "", *, pdeathsig: bool = False,
                     on_end: Callable[[], None] | None = None) -> None:
    """Ends this process (``on_end``) when process ``pid`` ends; see the module docstring."""
    kernel = pdeathsig and sys.platform.startswith("linux") and os.getppid() == pid
    if kernel:
        import ctypes

        kernel = ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, int(signal.SIGTERM)) == 0
    # the kernel signals this process itself: the watcher then only ends a stop that takes too long
    act = on_end or (_exit_after_grace if kernel else _terminate_self)
    if not alive(pid, start) or (pdeathsig and os.getppid() != pid):  # it ended before the lines above
        (on_end or _exit_now)()
        return
    threading.Thread(target=_watch, args=(pid, start, act), name="end-with-starter", daemon=True).start()


def _watch(pid: int, start: str, act: Callable[[], None]) -> None:
    fd = None
    if hasattr(os, "pidfd_open"):
        try:
            fd = os.pidfd_open(pid)
        except OSError:
            fd = None
    if fd is not None and alive(pid, start):  # opened on the right process: wait for it without polling
        import select

        poller = select.poll()
        poller.register(fd, select.POLLIN)
        while not poller.poll(1000):
            pass
        os.close(fd)
    else:
        while alive(pid, start):
            time.sleep(POLL_S)
    act()


def _exit_now() -> None:
    os._exit(143)


def _terminate_self() -> None:
    """SIGTERM to this process (its clean stop), then :func:`_exit_after_grace`."""
    try:
        os.kill(os.getpid(), signal.SIGTERM)
    finally:
        _exit_after_grace()


def _exit_after_grace() -> None:
    """``os._exit(143)`` if this process is still here :data:`GRACE_S` s from now (a clean stop that hangs)."""
    time.sleep(GRACE_S)
    os._exit(143)


def hang_up_as_terminate(handler: Callable | None = None) -> None:
    """SIGHUP (the terminal closed, ssh dropped) does what SIGTERM does in this process (main thread only), and
    what it would print to the gone terminal goes to /dev/null instead of failing; ``handler``: install this on
    both signals first. Ctrl-C (SIGINT) raises KeyboardInterrupt even where the process was started with SIGINT
    ignored (a background job of a script), as ros2 launch handles it whatever it inherited."""
    if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    if handler is not None:
        signal.signal(signal.SIGTERM, handler)
    term = signal.getsignal(signal.SIGTERM)

    def hung_up(signum, frame) -> None:  # noqa: ANN001 - the signal module's signature
        _detach_terminal()
        if callable(term):
            term(signal.SIGTERM, frame)
        elif term != signal.SIG_IGN:
            raise SystemExit(128 + int(signal.SIGTERM))

    signal.signal(signal.SIGHUP, hung_up)


def interrupt_on_terminate() -> None:
    """SIGTERM and SIGHUP raise KeyboardInterrupt in this process's main thread, as Ctrl-C does: a starter whose
    ``finally`` stops its graph and closes its bag does so whichever of the three came."""

    def interrupt(signum, frame) -> None:  # noqa: ANN001 - the signal module's signature
        raise KeyboardInterrupt

    hang_up_as_terminate(interrupt)


def _detach_terminal() -> None:
    """stdout, stderr and stdin to /dev/null where they are a terminal (which has gone after a SIGHUP)."""
    null = os.open(os.devnull, os.O_RDWR)
    for fd in (0, 1, 2):
        try:
            if os.isatty(fd):
                os.dup2(null, fd)
        except OSError:
            pass
    os.close(null)
