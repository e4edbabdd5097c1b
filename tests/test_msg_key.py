"""The graph's message key (avp_common.msg_auth.load_key) when the nodes started together all create it at once."""

from __future__ import annotations

import multiprocessing as mp
import stat
from pathlib import Path

PATHS = 300  # fresh key paths each process loads, in the same order as the others
PROCESSES = 4


def _load_all(base: str, barrier, results) -> None:
    from avp_common.msg_auth import load_key

    out: list[bytes | str] = []
    for i in range(PATHS):
        barrier.wait()  # all at once, path after path
        try:
            out.append(load_key(Path(base) / str(i) / "cmd.key"))
        except OSError as exc:  # a key file read while another process was still writing it
            out.append(str(exc))
    results.put(out)


def test_nodes_creating_the_key_at_once_all_get_the_one_key(tmp_path):
    """Four processes load 300 fresh key paths at once: each path ends with one key of 32 random bytes that every
    process got, no process reads a half-written file, and no temporary file is left beside the key."""
    ctx = mp.get_context("fork")
    barrier, results = ctx.Barrier(PROCESSES), ctx.Queue()
    procs = [ctx.Process(target=_load_all, args=(str(tmp_path), barrier, results)) for _ in range(PROCESSES)]
    for p in procs:
        p.start()
    got = [results.get(timeout=120) for _ in procs]
    for p in procs:
        p.join(30)
    errors = [k for run in got for k in run if isinstance(k, str)]
    assert not errors, f"{len(errors)} of {PROCESSES * PATHS} loads failed, e.g. {errors[0]}"
    for i in range(PATHS):
        on_disk = (tmp_path / str(i) / "cmd.key").read_bytes()
        assert {run[i] for run in got} == {on_disk} and len(on_disk) >= 16
        assert [p.name for p in (tmp_path / str(i)).iterdir()] == ["cmd.key"]
    assert stat.S_IMODE((tmp_path / "0" / "cmd.key").stat().st_mode) == 0o600
    assert stat.S_IMODE((tmp_path / "0").stat().st_mode) == 0o700
