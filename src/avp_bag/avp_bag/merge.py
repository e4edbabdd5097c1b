"""``avp merge-bag BAG OUT.mcap``: one MCAP file of a split bag, for viewers that open a single file (docs/foxglove.md).

The recorder finishes a storage file every second (crash safety, :mod:`avp_bag.recorder`); Foxglove and Lichtblick
open one file at a time. This copies every message of every split, in order, unchanged (the CDR bytes and log
times as recorded), into one ``ros2``-profile MCAP with each type's ``ros2msg`` definition and chunk CRCs. It
reads through :class:`avp_bag.reader.BagReader`, so a damaged bag is merged up to the damage (one warning)
or refused naming the file; ``OUT`` is never overwritten.
"""

from __future__ import annotations

from importlib.metadata import version
from pathlib import Path

from mcap.writer import CompressionType, Writer

from avp_bag.mcap_storage import CHUNK_SIZE
from avp_bag.reader import BagReader
from avp_bag.typestore import make_typestore


def merge_bag(bag: str | Path, out: str | Path) -> int:
    """Write every message of ``bag`` into the new file ``out``; returns how many."""
    reader = BagReader(bag)
    ts = make_typestore()
    schemas: dict[str, int] = {}
    channels: dict[str, int] = {}
    n = 0
    with open(out, "xb") as f:
        w = Writer(f, chunk_size=CHUNK_SIZE, compression=CompressionType.NONE, enable_crcs=True,
                   enable_data_crcs=True)
        w.start(profile="ros2", library=f"avp_bag merge-bag (mcap {version('mcap')})")
        for topic, msgtype, t, raw in reader.messages():
            if topic not in channels:
                if msgtype not in schemas:
                    msgdef, _ = ts.generate_msgdef(msgtype, ros_version=2)
                    schemas[msgtype] = w.register_schema(msgtype, "ros2msg", msgdef.encode())
                channels[topic] = w.register_channel(topic, "cdr", schemas[msgtype])
            w.add_message(channels[topic], int(t), bytes(raw), int(t))
            n += 1
        w.finish()
    return n
