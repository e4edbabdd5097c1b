"""One rosbag2 MCAP storage file written with the maintained `mcap` library, with chunk and data CRCs.

rosbags' own MCAP writer stores a CRC of 0 ("not computed") for every chunk and for the data section,
so a flipped bit inside a recorded chunk goes unnoticed by every reader. This writer keeps rosbags'
storage-plugin interface (``add_msgtype``, ``add_connection``, ``write``, ``close``; used by
:class:`avp_bag.writer.SplitBagWriter`) and the records rosbag2's MCAP plugin writes
(profile ``ros2``, ``ros2msg`` schemas, ``cdr`` channels with ``offered_qos_profiles`` and
``topic_type_hash``, a ``rosbag2`` metadata record), but lets ``mcap.writer.Writer`` lay out the file:
chunks of at most :data:`CHUNK_SIZE` bytes, each with the CRC-32 of its records, a summary and an index.
A reader that validates CRCs (``avp_bag.reader``, ``mcap``'s ``validate_crcs=True``) then refuses a
corrupt chunk instead of decoding garbage, and a file cut short still yields every complete chunk.
"""

from __future__ import annotations

import os
from importlib.metadata import version
from pathlib import Path

from mcap.writer import CompressionType, Writer

#: bytes of messages per chunk (rosbag2's MCAP default is 768 KiB; a chunk is the unit a reader salvages)
CHUNK_SIZE = 256 * 1024


class McapStorage:
    """``<path>/<path.name>.mcap``; the rosbags storage-writer interface (``compression`` must be NONE)."""

    def __init__(self, path: Path, compression=None, chunk_size: int = CHUNK_SIZE) -> None:
        self.path = Path(path) / f"{Path(path).name}.mcap"
        self._file = self.path.open("xb")
        self._writer = Writer(self._file, chunk_size=chunk_size, compression=CompressionType.NONE,
                              enable_crcs=True, enable_data_crcs=True)
        self._writer.start(profile="ros2", library=f"avp_bag (mcap {version('mcap')})")
        self._schemas: dict[str, int] = {}
        self._channels: dict[int, int] = {}
        self._closed = False

    def add_msgtype(self, connection) -> None:
        self._schemas[connection.msgtype] = self._writer.register_schema(
            connection.msgtype, "ros2msg", connection.msgdef.data.encode())

    def add_connection(self, connection, offered_qos_profiles: str) -> None:
        self._channels[connection.id] = self._writer.register_channel(
            connection.topic, "cdr", self._schemas[connection.msgtype],
            {"offered_qos_profiles": offered_qos_profiles, "topic_type_hash": connection.digest})

    def write(self, connection, timestamp: int, data: bytes | memoryview) -> None:
        self._writer.add_message(self._channels[connection.id], int(timestamp), bytes(data), int(timestamp))

    def close(self, version_: int, metadata: str) -> None:
        """Finish the file (summary, index, footer) and fsync it."""
        if self._closed:
            return
        self._closed = True
        try:
            self._writer.add_metadata("rosbag2", {"serialized_metadata": metadata})
            self._writer.finish()
            self._file.flush()
            os.fsync(self._file.fileno())
        finally:
            self._file.close()

    def abort(self) -> None:
        """Close the file as it is (no footer); what reached the disk stays readable chunk by chunk."""
        if self._closed:
            return
        self._closed = True
        try:
            self._file.close()
        except OSError:
            pass
