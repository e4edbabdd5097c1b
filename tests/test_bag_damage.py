"""Damaged bags and full disks (docs/bad_input.md rows 42-47), against the real CLI and real DDS.

The damage is made to a real recorded episode (bags/examples/demo_seed4_4s, rewritten by our writer in small
chunks so a cut falls inside one); the expected counts come from the `mcap` library reading the intact file.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

rclpy = pytest.importorskip("rclpy")

EXAMPLE = Path(__file__).resolve().parents[1] / "bags" / "examples" / "demo_seed4_4s"
CLI = [sys.executable, "-m", "avp_bringup.cli"]


def _rewrite(src: Path, dst: Path, chunk_size: int, extra_topic: tuple[str, str, str] | None = None) -> None:
    """Copy the bag ``src`` into one split of ``dst`` written by our writer with ``chunk_size``-byte chunks;
    ``extra_topic`` = (topic, type, definition) adds a topic of a type this installation does not know."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import get_types_from_msg

    from avp_bag.recorder import _qos
    from avp_bag.typestore import make_typestore
    from avp_bag.writer import SplitBagWriter

    ts = make_typestore()
    w = SplitBagWriter(dst, split_period=1e9, chunk_size=chunk_size)
    w.open()
    with AnyReader([src], default_typestore=ts) as reader:
        conns = {c.id: w.add_connection(c.topic, c.msgtype, typestore=ts,
                                        offered_qos_profiles=c.ext.offered_qos_profiles)
                 for c in reader.connections}
        extra = None
        if extra_topic:
            topic, typename, definition = extra_topic
            ts.register(get_types_from_msg(definition, typename))
            extra = w.add_connection(topic, typename, typestore=ts, offered_qos_profiles=[_qos(False)])
            cls = ts.types[typename]
        for c, t, raw in reader.messages():
            w.write(conns[c.id], t, raw)
            if extra is not None:
                w.write(extra, t, ts.serialize_cdr(cls(x=7), typename))
    w.close()


def _chunks(f: Path) -> list[tuple[int, int, int]]:
    """(start offset, length, messages) of every chunk, read by the `mcap` library."""
    from mcap.reader import SeekingReader
    from mcap.records import Chunk, Message
    from mcap.stream_reader import StreamReader, breakup_chunk

    with open(f, "rb") as fh:
        index = sorted(SeekingReader(fh).get_summary().chunk_indexes, key=lambda c: c.chunk_start_offset)
    with open(f, "rb") as fh:
        counts = [sum(isinstance(r, Message) for r in breakup_chunk(c))
                  for c in StreamReader(fh, emit_chunks=True).records if isinstance(c, Chunk)]
    return [(c.chunk_start_offset, c.chunk_length, n) for c, n in zip(index, counts, strict=True)]


@pytest.fixture(scope="module")
def chunked(tmp_path_factory) -> Path:
    bag = tmp_path_factory.mktemp("bags") / "chunked"
    _rewrite(EXAMPLE, bag, chunk_size=32 * 1024)
    return bag


def _run(args: list[str], env=None, timeout: float = 60) -> subprocess.CompletedProcess:
    return subprocess.run(CLI + args, env=env, capture_output=True, text=True, timeout=timeout)


def test_our_writer_stores_chunk_crcs_and_stays_readable_by_rosbags(chunked):
    from mcap.records import Chunk
    from mcap.stream_reader import StreamReader
    from rosbags.highlevel import AnyReader

    f = chunked / "chunked_0.mcap"
    with open(f, "rb") as fh:
        chunks = [r for r in StreamReader(fh, emit_chunks=True, validate_crcs=True).records if isinstance(r, Chunk)]
    assert len(chunks) >= 8 and all(c.uncompressed_crc != 0 for c in chunks)
    with AnyReader([EXAMPLE]) as a, AnyReader([chunked]) as b:
        assert [bytes(r) for _, _, r in a.messages()] == [bytes(r) for _, _, r in b.messages()]


def test_metrics_and_replay_of_a_bag_cut_mid_chunk(chunked, tmp_path, ros_env):
    """Cut inside chunk k: the messages of chunks 0..k-1 are read (the warning says how many)."""
    from mcap.reader import SeekingReader

    bag = tmp_path / "cut"
    shutil.copytree(chunked, bag)
    f = bag / "chunked_0.mcap"
    chunks = _chunks(f)
    k = len(chunks) // 2
    start, length, _ = chunks[k]
    expected = sum(n for *_, n in chunks[:k])
    f.write_bytes(f.read_bytes()[:start + length // 2])
    with pytest.raises(Exception):  # noqa: B017 - the mcap library itself refuses the file
        with open(f, "rb") as fh:
            SeekingReader(fh).get_summary()
    m = _run(["metrics", str(bag)], env=ros_env)
    assert f"{f}: cut short" in m.stderr and f"read {expected} messages" in m.stderr, m.stderr
    assert m.returncode in (0, 1, 2) and "Traceback" not in m.stderr
    from avp_bag.reader import BagReader

    got = list(BagReader(bag, warn=lambda _t: None).messages())
    assert len(got) == expected
    r = _run(["replay", str(bag), "--rate", "0", "--delay", "0.2"], env=ros_env)
    assert r.returncode == 0, r.stderr
    assert f"published {expected} messages" in r.stdout and f"{f}: cut short" in r.stderr


def test_metrics_and_replay_refuse_a_corrupt_chunk_naming_the_file(chunked, tmp_path, ros_env):
    bag = tmp_path / "crc"
    shutil.copytree(chunked, bag)
    f = bag / "chunked_0.mcap"
    start, length, _ = _chunks(f)[3]
    data = bytearray(f.read_bytes())
    data[start + length // 2] ^= 0x5A  # one flipped byte inside chunk 3's messages
    f.write_bytes(bytes(data))
    for args in (["metrics", str(bag)], ["replay", str(bag), "--rate", "0", "--delay", "0"]):
        r = _run(args, env=ros_env)
        assert r.returncode == 2, r.stdout + r.stderr
        assert f"{f}: chunk 4 fails its CRC check" in r.stderr and "Traceback" not in r.stderr


def test_unknown_message_type_is_skipped_with_one_warning(tmp_path, ros_env):
    bag = tmp_path / "unknown"
    _rewrite(EXAMPLE, bag, chunk_size=256 * 1024, extra_topic=("/acme/widget", "acme_msgs/msg/Widget", "int32 x"))
    m = _run(["metrics", str(bag)], env=ros_env)
    assert m.returncode == 0, m.stderr  # the episode's topics are intact: the recomputed metrics equal the live
    assert m.stderr.count("acme_msgs/msg/Widget, which this installation does not know") == 1
    assert f"{bag / 'unknown_0.mcap'}: topic /acme/widget" in m.stderr
    r = _run(["replay", str(bag), "--rate", "0", "--delay", "0", "--topics", "/acme/widget"], env=ros_env)
    assert r.returncode == 2 and "no topic(s) ['/acme/widget'] of a known type" in r.stderr


def test_empty_and_foreign_files_get_one_error_naming_them(tmp_path, ros_env):
    empty = tmp_path / "empty.mcap"
    empty.write_bytes(b"")
    text = tmp_path / "notes.mcap"
    text.write_text("not a bag\n")
    bag = tmp_path / "emptysplit"
    shutil.copytree(EXAMPLE, bag)
    (bag / "demo_seed4_4s.mcap").write_bytes(b"")
    cases = [(empty, "empty file (0 bytes)"), (text, "not an MCAP file"),
             (bag, "empty file (0 bytes)"), (tmp_path / "nothing", "no such bag")]
    for path, reason in cases:
        for cmd in ("metrics", "replay"):
            r = _run([cmd, str(path)], env=ros_env)
            assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
            assert reason in r.stderr and str(path) in r.stderr, r.stderr


@pytest.fixture()
def small_fs(tmp_path):
    """A 1 MiB tmpfs (less than the 4 s demo's bag, about 1.4 MB), or a skip saying why it cannot be made here. Not
    smaller: the bag's first splits and its first 256 KiB chunk must fit before the disk fills (with 512 KiB, a fast
    machine that put the whole episode in one split read back an empty prefix)."""
    import os

    mnt = tmp_path / "small"
    mnt.mkdir()
    if os.geteuid() != 0:
        pytest.skip(f"mounting a size-limited tmpfs needs root; this test runs as uid {os.geteuid()}")
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=1m", "tmpfs", str(mnt)], capture_output=True, text=True)
    if r.returncode != 0:
        pytest.skip(f"cannot mount a size-limited tmpfs here: {r.stderr.strip()}")
    try:
        yield mnt
    finally:
        subprocess.run(["umount", "-l", str(mnt)], check=False)


def test_disk_full_while_recording_stops_the_recorder_not_the_episode(small_fs, tmp_path, ros_env):
    """The demo records into a file system that fills before the end: one error, the episode runs to
    its end with the same metrics as the committed recording of that episode, the bag reads back a prefix."""
    import json

    from avp_bag.episode import metrics_from_bag
    from avp_bag.reader import BagReader

    bag, out = small_fs / "bag", tmp_path / "out"
    r = _run(["demo", "--seed", "4", "--t-final", "4", "--no-gif", "--bag", str(bag), "--out", str(out)],
             env=ros_env, timeout=300)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    assert r.stderr.count("recording stopped:") == 1, r.stderr[-3000:]
    assert "No space left on device" in r.stderr
    metrics = json.loads((out / "metrics.json").read_text())
    _, live = metrics_from_bag(EXAMPLE)
    assert metrics["steps"] == live["steps"] == 40 and metrics["state"] == live["state"]
    reader = BagReader(bag, warn=lambda _t: None)
    steps = [int(reader.deserialize(raw, t).step) for _, t, _, raw in reader.messages(["/avp/debug/ground_truth"])]
    # a readable prefix, then the disk was full (the stop above). It may have filled on a larger message of another
    # topic after the last ground truth was written (a loaded machine orders the writes differently): at most the
    # episode's 41 ground truths, of steps 0 to 40 (the last one, of the state the episode ended in, included)
    assert steps and steps == list(range(len(steps))) and len(steps) <= live["steps"] + 1
