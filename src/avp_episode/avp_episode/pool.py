"""The local backend's worker processes (``avp experiment --workers N``): one pool per run, or one for a whole suite.

:func:`~.runner.run_inproc` makes a pool for its run. A suite (``--suite``, :mod:`.headline`) runs dozens of cells,
many of a few episodes (``--quick``), and starting two workers (torch, the intent CNN, the lot) took about as long as
a small cell's episodes: :func:`shared_pool` keeps one pool for every cell, and each cell's episodes go to it with
their cell's settings (:func:`~.episodes.episode_in_worker`: a worker sets itself up again only when the settings
change, as a Ray worker does). Which worker runs an episode never changes its record.
"""

from __future__ import annotations

import contextlib
import sys
from collections.abc import Callable, Iterator
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from multiprocessing import get_context

from avp_episode.run_config import Key


def worker_signals() -> None:
    """A pool worker's signals: it leaves Ctrl-C to the parent, which lets the running episodes finish and records
    them, and it ends with its parent, however the parent ended (:func:`end_with_parent`)."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    end_with_parent()


def end_with_parent() -> None:
    """This process ends when the process that started it ends (avp_common.lifetime: ``PR_SET_PDEATHSIG`` on Linux, a
    watcher of the parent's pid elsewhere), so that a killed ``avp experiment`` (SIGKILL, the OOM killer) leaves no
    workers behind holding a torch model each."""
    import multiprocessing

    from avp_common.lifetime import end_with_process, start_time

    parent = multiprocessing.parent_process()
    if parent is None or parent.pid is None:
        return
    end_with_process(parent.pid, start_time(parent.pid), pdeathsig=True)


@contextlib.contextmanager
def end_workers_on_sigterm(message: str) -> Iterator[None]:
    """While inside (main thread only, where signal handlers live), SIGTERM (and SIGHUP, a closed terminal) prints
    ``message`` and exits with status 143: with pool workers, it ends them and exits at once; without, it raises
    ``SystemExit(143)``. A scheduler's
    SIGTERM (Slurm, systemd) leaves seconds before its SIGKILL, not the minutes a running episode may take; the
    records already written stay (each line is fsync'ed, :class:`~.results.ResultsWriter`), and the same command
    runs the rest."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def terminated(signum, frame) -> None:
        import multiprocessing
        import os

        print(message, file=sys.stderr, flush=True)
        workers = multiprocessing.active_children()
        if not workers:  # in process, Ray, a DDS graph: through the callers' finally blocks (graph.stop())
            raise SystemExit(143)
        for child in workers:  # a pool whose workers are ended cannot be shut down cleanly (CPython 3.11's
            child.terminate()  # executor thread raises InvalidStateError on the cancelled episodes): exit now
        for child in workers:
            child.join(5.0)
        os._exit(143)

    before = signal.signal(signal.SIGTERM, terminated)
    before_hup = signal.getsignal(signal.SIGHUP)
    from avp_common.lifetime import hang_up_as_terminate

    hang_up_as_terminate()  # SIGHUP (the terminal closed) as SIGTERM
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, before)
        signal.signal(signal.SIGHUP, before_hup)


def make_pool(workers: int, initializer: Callable | None = None, initargs: tuple = ()) -> ProcessPoolExecutor:
    """``workers`` spawned processes (torch and a forked parent do not mix)."""
    return ProcessPoolExecutor(max_workers=workers, mp_context=get_context("spawn"),
                               initializer=initializer or worker_signals, initargs=initargs)


@contextlib.contextmanager
def shared_pool(workers: int) -> Iterator[ProcessPoolExecutor | None]:
    """One pool for several runs (None when ``workers`` <= 0: the runs go in this process)."""
    if workers <= 0:
        yield None
        return
    pool = make_pool(workers)
    try:
        yield pool
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def collect(pending: dict[Future, Key], on_record: Callable, failed: Callable[[Key, BaseException], None]) -> None:
    """Hand each finished episode's record to ``on_record`` as it comes, and each error to ``failed``. On Ctrl-C the
    queued episodes are cancelled and the running ones recorded; on any other exception the queued ones are
    cancelled, so that nothing runs unrecorded."""
    try:
        while pending:
            done, _ = wait(pending, return_when=FIRST_COMPLETED)
            for f in done:
                key = pending.pop(f)
                try:
                    r = f.result()
                except BrokenProcessPool:
                    raise
                except Exception as exc:  # noqa: BLE001 - one episode's bug must not stop the sweep
                    failed(key, exc)
                    continue
                on_record(r)
    except KeyboardInterrupt:
        running = {f for f in pending if not f.cancel()}
        print(f"\n[avp experiment] interrupted: finishing the {len(running)} running episode(s)", file=sys.stderr,
              flush=True)
        for f in running:
            with contextlib.suppress(Exception):  # keep what finished, report the interruption
                on_record(f.result())
        raise
    except BaseException:
        for f in pending:
            f.cancel()
        raise
