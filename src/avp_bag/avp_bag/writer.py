"""A crash-safe rosbag2 writer: the bag is a sequence of *finished* storage files ("splits").

rosbags' :class:`~rosbags.rosbag2.Writer` keeps the MCAP summary (schemas, channels, chunk index) and
``metadata.yaml`` for :meth:`close`; a SIGKILLed recorder leaves a file without footer or index and no
metadata, which no reader opens. :class:`SplitBagWriter` instead rotates to a new storage file every
``split_period`` wall seconds (the same split scheme as ``ros2 bag record --max-bag-duration``):

* the open split is written inside a hidden sub-directory ``.<name>_<k>.partial/`` (rosbags' storage
  writers name their file after the directory);
* finishing a split closes it with its storage writer (summary, index and footer written; MCAP through
  :class:`avp_bag.mcap_storage.McapStorage`, whose chunks carry CRCs, SQLite through rosbags'), moves
  the file into the bag directory as ``<name>_<k>.mcap`` and then rewrites ``metadata.yaml`` atomically
  (write to a temporary file, ``os.replace``) listing the finished splits only.

So at any instant the bag directory holds a readable rosbag2 whose messages are a prefix of what was
written: a crash loses at most the open split (the last ``split_period`` seconds). ``close`` finishes the
open split; splits are read back in order by any rosbag2 reader (rosbags' ``AnyReader``, ``ros2 bag``).

A write that fails (disk full, file system gone read-only: any ``OSError``) stops the writer for good
with one :class:`BagStorageError` naming the bag and the cause: the open split is closed as it is and
moved into the bag as ``<name>_<k>.mcap`` without a footer (``avp_bag.reader`` reads its complete
chunks, with a warning), ``metadata.yaml`` keeps listing the finished splits, and nothing already on
disk is touched. The caller (the recorder) keeps running.
"""

from __future__ import annotations

import os
import shutil
import time
from pathlib import Path

import yaml
from rosbags.interfaces import (
    Connection,
    ConnectionExtRosbag2,
    MessageDefinition,
    MessageDefinitionFormat,
    Qos,
)
from rosbags.rosbag2.enums import CompressionMode
from rosbags.rosbag2.metadata import dump_qos_v9
from rosbags.rosbag2.storage_sqlite3 import Sqlite3Writer

from avp_bag.mcap_storage import CHUNK_SIZE, McapStorage

VERSION = 9
_PLUGINS = {"mcap": (McapStorage, ".mcap"), "sqlite3": (Sqlite3Writer, ".db3")}



#: libyaml's emitter where PyYAML was built with it (the same text as yaml.safe_dump, about 8 times faster: the
#: metadata of every split is written again each ``split_period``), else PyYAML's own
_DUMPER = getattr(yaml, "CSafeDumper", yaml.SafeDumper)


def _yaml(data, sort_keys: bool = True) -> str:
    """``yaml.safe_dump(data, default_flow_style=False, sort_keys=sort_keys)``, on :data:`_DUMPER`."""
    return yaml.dump(data, Dumper=_DUMPER, default_flow_style=False, sort_keys=sort_keys)


class BagWriteError(ValueError):
    """The bag cannot be created (exists already, unknown storage, ...)."""


class BagStorageError(BagWriteError):
    """Writing failed on the file system (disk full, ...): the writer has stopped; the bag stays readable."""


class SplitBagWriter:
    """rosbag2 directory written as finished splits; see the module docstring.

    Args:
        path: the bag directory (must not exist).
        storage: ``"mcap"`` or ``"sqlite3"``.
        split_period: wall seconds after which a non-empty open split is finished (``maybe_rotate``).
        chunk_size: bytes of messages per MCAP chunk (the unit a damaged split is read back in).
    """

    def __init__(self, path: str | Path, storage: str = "mcap", split_period: float = 1.0,
                 chunk_size: int = CHUNK_SIZE) -> None:
        self.path = Path(path)
        if storage not in _PLUGINS:
            raise BagWriteError(f"{self.path}: unknown storage {storage!r}; one of {sorted(_PLUGINS)}")
        if not split_period > 0:
            raise BagWriteError(f"{self.path}: split_period must be > 0, got {split_period}")
        self.storage_id = storage
        self.split_period = float(split_period)
        self.chunk_size = int(chunk_size)
        self.connections: list[Connection] = []
        self._dumped_qos: list[str] = []
        self.counts: dict[int, int] = {}  # finished splits, per connection id
        self.files: list[dict] = []  # finished splits (metadata 'files' entries)
        self._storage = None
        self._split_dir: Path | None = None
        self._split_counts: dict[int, int] = {}
        self._split_times = [2**63 - 1, 0]
        self._split_opened = 0.0
        self._open = False
        self.error: str | None = None  # why writing stopped (BagStorageError), else None
        self.written = 0  # messages handed to the storage, this split included

    # ------------------------------------------------------------------------------------------ life cycle
    def open(self) -> None:
        try:
            self.path.mkdir(mode=0o755, parents=True)
        except FileExistsError:
            raise BagWriteError(f"{self.path} exists already, not overwriting") from None
        self._open = True
        self._write_metadata()  # an empty but readable bag from the start
        self._open_split()

    def close(self) -> None:
        """Finish the open split and write the final metadata."""
        if not self._open:
            return
        self._open = False
        self._guarded(self._finish_split)

    @property
    def closed(self) -> bool:
        return not self._open

    # ------------------------------------------------------------------------------------------ writing
    def add_connection(self, topic: str, msgtype: str, *, typestore, offered_qos_profiles: list[Qos]) -> Connection:
        if not self._open:
            raise BagWriteError(f"{self.path}: bag is not open")
        msgdef, _ = typestore.generate_msgdef(msgtype, ros_version=2)
        conn = Connection(id=len(self.connections) + 1, topic=topic, msgtype=msgtype,
                          msgdef=MessageDefinition(MessageDefinitionFormat.MSG, msgdef),
                          digest=typestore.hash_rihs01(msgtype), msgcount=0,
                          ext=ConnectionExtRosbag2(serialization_format="cdr",
                                                   offered_qos_profiles=list(offered_qos_profiles)),
                          owner=self)
        self.connections.append(conn)
        self._dumped_qos.append(_yaml(dump_qos_v9(list(offered_qos_profiles))))
        self.counts[conn.id] = 0
        self._register(conn, self._dumped_qos[-1], {c.msgtype for c in self.connections[:-1]})
        return conn

    def write(self, conn: Connection, timestamp: int, data: bytes | memoryview) -> None:
        if not self._open:
            raise BagWriteError(f"{self.path}: bag is not open" + (f" ({self.error})" if self.error else ""))
        self._guarded(self._storage.write, conn, int(timestamp), data)
        self.written += 1
        self._split_counts[conn.id] = self._split_counts.get(conn.id, 0) + 1
        self._split_times = [min(self._split_times[0], timestamp), max(self._split_times[1], timestamp)]
        self.maybe_rotate()

    def maybe_rotate(self, now: float | None = None) -> bool:
        """Finish the open split if it holds messages and is ``split_period`` old; True when it rotated."""
        now = time.monotonic() if now is None else now
        if self._open and self._split_counts and now - self._split_opened >= self.split_period:
            self.rotate()
            return True
        return False

    def rotate(self) -> None:
        """Finish the open split (it becomes readable) and start a new one."""
        self._guarded(self._finish_split)
        self._guarded(self._open_split)

    # ------------------------------------------------------------------------------------------ failure
    def _guarded(self, fn, *args) -> None:
        try:
            fn(*args)
        except OSError as exc:
            self._stop(exc)

    def _stop(self, exc: OSError) -> None:
        """Stop writing after ``exc``: keep what reached the disk, raise one :class:`BagStorageError`."""
        self._open = False
        storage, split_dir = self._storage, self._split_dir
        self._storage, self._split_dir = None, None
        kept = ""
        if storage is not None:
            try:
                storage.abort()
            except Exception:  # noqa: BLE001 - the file system failed already; keep the first error
                pass
            src = Path(storage.path)
            dst = self.path / f"{self.path.name}_{len(self.files)}{_PLUGINS[self.storage_id][1]}"
            try:
                if src.exists() and src.stat().st_size > 0:
                    os.replace(src, dst)
                    kept = f"; the split being written is kept as {dst.name} (read up to its last complete chunk)"
            except OSError:
                pass
        if split_dir is not None:
            shutil.rmtree(split_dir, ignore_errors=True)
        reason = exc.strerror or str(exc)
        self.error = (f"{self.path}: writing failed ({reason}); recording stopped after {self.written} messages, "
                      f"{sum(self.counts.values())} of them in {len(self.files)} finished split(s) listed in "
                      f"metadata.yaml{kept}")
        raise BagStorageError(self.error) from exc

    # ------------------------------------------------------------------------------------------ internals
    def _register(self, conn: Connection, dumped_qos: str, known_types: set[str]) -> None:
        if conn.msgtype not in known_types:
            self._storage.add_msgtype(conn)
        self._storage.add_connection(conn, dumped_qos)

    def _open_split(self) -> None:
        k = len(self.files)
        self._split_dir = self.path / f".{self.path.name}_{k}.partial"
        self._split_dir.mkdir()
        if self.storage_id == "mcap":
            self._storage = McapStorage(self._split_dir, chunk_size=self.chunk_size)
        else:
            self._storage = Sqlite3Writer(self._split_dir, CompressionMode.NONE)
        seen: set[str] = set()
        for conn, dumped in zip(self.connections, self._dumped_qos, strict=True):
            self._register(conn, dumped, seen)
            seen.add(conn.msgtype)
        self._split_counts = {}
        self._split_times = [2**63 - 1, 0]
        self._split_opened = time.monotonic()

    def _finish_split(self) -> None:
        storage, split_dir = self._storage, self._split_dir
        if storage is None or split_dir is None:
            return
        if not self._split_counts:  # nothing written: drop it
            storage.close(VERSION, "")
            self._storage, self._split_dir = None, None
            shutil.rmtree(split_dir, ignore_errors=True)
            self._write_metadata()
            return
        name = f"{self.path.name}_{len(self.files)}{_PLUGINS[self.storage_id][1]}"
        t0, t1 = self._split_times
        entry = {"path": name, "starting_time": {"nanoseconds_since_epoch": t0}, "duration": {"nanoseconds": t1 - t0},
                 "message_count": sum(self._split_counts.values())}
        storage.close(VERSION, _yaml(self._info([entry], self._split_counts)))
        os.replace(storage.path, self.path / name)
        self._storage, self._split_dir = None, None
        shutil.rmtree(split_dir, ignore_errors=True)
        for cid, n in self._split_counts.items():
            self.counts[cid] += n
        self.files.append(entry)
        self._split_counts = {}
        self._write_metadata()

    def _info(self, files: list[dict], counts: dict[int, int]) -> dict:
        """The ``rosbag2_bagfile_information`` block for ``files`` (rosbag2 metadata version 9)."""
        t0 = min((f["starting_time"]["nanoseconds_since_epoch"] for f in files), default=0)
        t1 = max((f["starting_time"]["nanoseconds_since_epoch"] + f["duration"]["nanoseconds"] for f in files),
                 default=0)
        return {
            "version": VERSION,
            "storage_identifier": self.storage_id,
            "relative_file_paths": [f["path"] for f in files],
            "duration": {"nanoseconds": t1 - t0},
            "starting_time": {"nanoseconds_since_epoch": t0},
            "message_count": sum(f["message_count"] for f in files),
            "topics_with_message_count": [
                {"topic_metadata": {"name": c.topic, "type": c.msgtype, "serialization_format": "cdr",
                                    "offered_qos_profiles": dump_qos_v9(c.ext.offered_qos_profiles),
                                    "type_description_hash": c.digest},
                 "message_count": int(counts.get(c.id, 0))}
                for c in self.connections
            ],
            "compression_format": "",
            "compression_mode": "",
            "files": files,
            "custom_data": None,
            "ros_distro": "rosbags",
        }

    def _write_metadata(self) -> None:
        text = _yaml({"rosbag2_bagfile_information": self._info(self.files, self.counts)}, sort_keys=False)
        tmp = self.path / "metadata.yaml.tmp"
        try:
            with open(tmp, "w", encoding="utf8") as f:
                f.write(text)
                f.flush()
                os.fsync(f.fileno())
            os.replace(tmp, self.path / "metadata.yaml")
        except OSError:
            tmp.unlink(missing_ok=True)  # the previous metadata.yaml stays, whole
            raise
