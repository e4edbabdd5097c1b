"""Read a recorded bag defensively: every split checked, a cut split salvaged, one clear error.

``avp replay``, ``avp metrics`` and the episode video read bags through :class:`BagReader`, which takes a
rosbag2 directory (``metadata.yaml`` + splits) or a single ``.mcap`` file and streams its MCAP records with
the maintained ``mcap`` reader, validating every chunk's CRC:

* an empty file, a file that is not MCAP, a chunk whose CRC does not match its bytes, a record longer than
  :data:`MAX_RECORD_BYTES` or an unknown compression: :class:`BagReadError` naming the file (and the chunk);
* a split cut short (a crashed laptop, a full disk): its complete chunks are read, then one warning names the
  file and the number of messages read before the cut; the next splits are read as usual;
* a split in the directory that ``metadata.yaml`` does not list (the recorder stopped while writing it):
  read, with a warning;
* a topic whose type this installation does not know: skipped, with one warning naming the file, topic, type.

SQLite3 bags (``avp record --storage sqlite3``) go through rosbags' ``AnyReader``, its errors re-raised as
:class:`BagReadError`.
"""

from __future__ import annotations

import re
import struct
import sys
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path

from avp_bag.typestore import make_typestore
from avp_world.safe_yaml import YamlInputError, load_bounded, read_bounded

MAGIC = b"\x89MCAP0\r\n"
#: longest MCAP record read (a chunk holds 256 KiB of messages; a single BEV image is < 1 MiB)
MAX_RECORD_BYTES = 64 * 2**20
MAX_METADATA_BYTES = 4 * 2**20


class BagReadError(ValueError):
    """The bag (or one of its files) cannot be read; the message names the file."""


@dataclass(frozen=True)
class BagTopic:
    name: str
    msgtype: str
    latched: bool


def _warn_stderr(text: str) -> None:
    print(f"[avp bag] warning: {text}", file=sys.stderr, flush=True)


class BagReader:
    """Messages of a bag as ``(topic, msgtype, log_time_ns, cdr_bytes)``; see the module docstring."""

    def __init__(self, path: str | Path, warn: Callable[[str], None] | None = None) -> None:
        self.path = Path(path)
        self.warn = warn or _warn_stderr
        self.warnings: list[str] = []
        self.typestore = make_typestore()
        self.storage, self.files, self.meta_topics = self._layout()
        self._reported: set[tuple[str, str]] = set()
        self.topics: dict[str, BagTopic] = {}
        if self.storage == "sqlite3":
            self._any_topics()
        else:
            for f in self.files:
                self._check_head(f)
            self._scan_topics()

    # ------------------------------------------------------------------------------------------ public
    def deserialize(self, raw: bytes, msgtype: str):
        return self.typestore.deserialize_cdr(raw, msgtype)

    def known(self, msgtype: str) -> bool:
        return msgtype in self.typestore.fielddefs

    def messages(self, topics: Iterable[str] | None = None) -> Iterator[tuple[str, str, int, bytes]]:
        """Every message of ``topics`` (all known ones if None), split after split, in log-time order."""
        wanted = None if topics is None else set(topics)
        if self.storage == "sqlite3":
            yield from self._any_messages(wanted)
            return
        for f in self.files:
            yield from self._file_messages(f, wanted)

    # ------------------------------------------------------------------------------------------ layout
    def _note(self, text: str) -> None:
        self.warnings.append(text)
        self.warn(text)

    def _layout(self) -> tuple[str, list[Path], dict[str, dict]]:
        p = self.path
        if not p.exists():
            raise BagReadError(f"{p}: no such bag (neither a rosbag2 directory nor a file)")
        if p.is_file():
            return "mcap", [p], {}
        meta = p / "metadata.yaml"
        info: dict = {}
        if meta.is_file():
            try:
                doc = load_bounded(read_bounded(meta, MAX_METADATA_BYTES), str(meta), MAX_METADATA_BYTES)
                info = (doc or {})["rosbag2_bagfile_information"]
                listed = [p / str(f) for f in info.get("relative_file_paths") or []]
                storage = str(info.get("storage_identifier", "mcap"))
            except (YamlInputError, OSError, KeyError, TypeError, AttributeError) as exc:
                raise BagReadError(f"{meta}: not rosbag2 metadata ({exc})") from None
        else:
            listed, storage = [], "mcap"
        if storage not in ("mcap", "sqlite3"):
            raise BagReadError(f"{meta}: storage_identifier {storage!r} is neither mcap nor sqlite3")
        for f in listed:
            if not f.is_file():
                raise BagReadError(f"{f}: listed in {meta} but missing")
        ext = ".mcap" if storage == "mcap" else ".db3"
        files = list(listed)
        for f in sorted(p.glob(f"*{ext}"), key=_split_index):
            if f not in files:
                if listed:
                    self._note(f"{f}: not listed in {meta} (the recorder stopped while writing it); reading it too")
                files.append(f)
        if not files:
            what = "" if meta.is_file() else "no metadata.yaml and "
            raise BagReadError(f"{p}: not a bag: {what}no {ext} storage file in the directory")
        topics = {}
        for t in info.get("topics_with_message_count") or []:
            try:
                topics[t["topic_metadata"]["name"]] = t["topic_metadata"]
            except (KeyError, TypeError):
                continue
        return storage, files, topics

    @staticmethod
    def _check_head(f: Path) -> None:
        try:
            size = f.stat().st_size
            with open(f, "rb") as fh:
                head = fh.read(len(MAGIC))
        except OSError as exc:
            raise BagReadError(f"{f}: cannot be read ({exc.strerror or exc})") from None
        if size == 0:
            raise BagReadError(f"{f}: empty file (0 bytes), not an MCAP storage file")
        if head != MAGIC:
            raise BagReadError(f"{f}: not an MCAP file (it does not start with the MCAP magic bytes)")

    # ------------------------------------------------------------------------------------------ MCAP
    def _scan_topics(self) -> None:
        """Channels of every file, from its summary; a file without one (cut short) is streamed for them (its
        damage is reported when its messages are read)."""
        from mcap.reader import SeekingReader

        for f in self.files:
            summary = None
            try:
                with open(f, "rb") as fh:
                    summary = SeekingReader(fh, record_size_limit=MAX_RECORD_BYTES).get_summary()
            except Exception:  # noqa: BLE001 - any damage: fall back to streaming the records
                summary = None
            if summary is not None:
                for ch in summary.channels.values():
                    sch = summary.schemas.get(ch.schema_id)
                    self._add_topic(f, ch.topic, sch.name if sch else "", str(ch.metadata.get("offered_qos_profiles",
                                                                                               "")))
                continue
            for kind, rec in self._records(f, quiet=True):
                if kind == "channel":
                    self._add_topic(f, *rec)

    def _add_topic(self, f: Path, topic: str, msgtype: str, qos_text: str) -> None:
        if topic in self.topics:
            return
        if not self.known(msgtype):
            if (topic, msgtype) not in self._reported:
                self._reported.add((topic, msgtype))
                self._note(f"{f}: topic {topic} has type {msgtype}, which this installation does not know; "
                           "its messages are skipped")
            return
        meta_qos = str((self.meta_topics.get(topic) or {}).get("offered_qos_profiles", ""))
        latched = "transient_local" in (qos_text or meta_qos)
        self.topics[topic] = BagTopic(topic, msgtype, latched)

    def _records(self, f: Path, quiet: bool = False) -> Iterator[tuple[str, tuple]]:
        """("channel", (topic, type, qos)) and ("message", (topic, type, t, data)) of one file, chunk by chunk
        (each chunk's messages in log-time order). ``quiet``: stop at damage without a word."""
        from mcap.exceptions import EndOfFile, InvalidMagic, RecordLengthLimitExceeded, UnsupportedCompressionError
        from mcap.records import Channel, Chunk, Message, Schema
        from mcap.stream_reader import CRCValidationError, StreamReader, breakup_chunk

        schemas: dict[int, str] = {}
        channels: dict[int, tuple[str, str]] = {}
        n_read, n_chunk = 0, 0

        def handle(rec):
            nonlocal n_read
            if isinstance(rec, Schema):
                schemas[rec.id] = rec.name
            elif isinstance(rec, Channel):
                msgtype = schemas.get(rec.schema_id, "")
                channels[rec.id] = (rec.topic, msgtype)
                return "channel", (rec.topic, msgtype, str(rec.metadata.get("offered_qos_profiles", "")))
            elif isinstance(rec, Message) and rec.channel_id in channels:
                n_read += 1
                return "message", (*channels[rec.channel_id], rec.log_time, rec.data)
            return None

        with open(f, "rb") as fh:
            reader = StreamReader(fh, emit_chunks=True, validate_crcs=False, record_size_limit=MAX_RECORD_BYTES)
            try:
                for rec in reader.records:
                    if isinstance(rec, Chunk):
                        n_chunk += 1
                        inner = [x for x in map(handle, breakup_chunk(rec, validate_crc=True)) if x]
                        yield from (x for x in inner if x[0] == "channel")
                        yield from sorted((x for x in inner if x[0] == "message"), key=lambda x: x[1][2])
                    else:
                        out = handle(rec)
                        if out:
                            yield out
            except (EndOfFile, InvalidMagic, struct.error) as exc:
                if not quiet:
                    self._note(f"{f}: cut short ({f.stat().st_size} bytes, no footer: {type(exc).__name__}): read "
                               f"{n_read} messages from its complete chunks; the rest of this split is lost")
            except CRCValidationError as exc:
                if not quiet:
                    raise BagReadError(f"{f}: chunk {n_chunk} fails its CRC check (recorded {exc.expected:#010x}, "
                                       f"computed {exc.actual:#010x}): the file is corrupt; {n_read} messages "
                                       "before it were read") from None
            except (RecordLengthLimitExceeded, UnsupportedCompressionError, ValueError, KeyError) as exc:
                if not quiet:
                    raise BagReadError(f"{f}: unreadable MCAP record after {n_read} messages "
                                       f"({type(exc).__name__}: {exc})") from None

    def _file_messages(self, f: Path, wanted: set[str] | None) -> Iterator[tuple[str, str, int, bytes]]:
        for kind, rec in self._records(f):
            if kind == "message" and rec[0] in self.topics and (wanted is None or rec[0] in wanted):
                yield rec[0], rec[1], rec[2], bytes(rec[3])

    # ------------------------------------------------------------------------------------------ SQLite3
    def _any(self):
        from rosbags.highlevel import AnyReader

        return AnyReader([self.path], default_typestore=self.typestore)

    def _any_topics(self) -> None:
        from rosbags.highlevel import AnyReaderError

        try:
            with self._any() as reader:
                for c in reader.connections:
                    qos = getattr(c.ext, "offered_qos_profiles", []) or []
                    self._add_topic(self.path, c.topic, c.msgtype,
                                    "transient_local" if qos and qos[0].durability.name == "TRANSIENT_LOCAL" else "")
        except (AnyReaderError, OSError) as exc:
            raise BagReadError(f"{self.path}: {exc}") from None

    def _any_messages(self, wanted: set[str] | None) -> Iterator[tuple[str, str, int, bytes]]:
        from rosbags.highlevel import AnyReaderError

        try:
            with self._any() as reader:
                conns = [c for c in reader.connections if c.topic in self.topics and (wanted is None or c.topic in
                                                                                       wanted)]
                for conn, t, raw in reader.messages(connections=conns):
                    yield conn.topic, conn.msgtype, t, bytes(raw)
        except (AnyReaderError, OSError) as exc:
            raise BagReadError(f"{self.path}: {exc}") from None


def _split_index(f: Path) -> tuple[int, str]:
    m = re.search(r"_(\d+)\.\w+$", f.name)
    return (int(m.group(1)) if m else -1, f.name)


__all__ = ["BagReadError", "BagReader", "BagTopic", "MAX_RECORD_BYTES"]
