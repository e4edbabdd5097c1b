"""Authenticated ego commands (issue #20 item 9): only a holder of the user's command key can steer the ego.

The Fast DDS of the ROS 2 wheels has no DDS security (no SROS2), and Jazzy's rclpy does not tell a subscriber
which writer sent a message, so the simulator cannot tell the planner's ``cmd`` from another process's by
origin. Instead every command carries a tag: ``header.frame_id = "<frame>#<tag>"`` with ``tag`` = the first
32 hex digits of HMAC-SHA256(key, "avp-cmd" | frame | stamp [ns] | v | ω) (v, ω as float64). The simulator
(``cmd_auth: true``) drops a command whose tag does not verify and names the publishers on ``cmd``. A copied
command is the planner's own (same stamp, same values); a new one cannot be forged without the key.

The key: 32 random bytes in ``$AVP_CMD_KEY_FILE``, default ``~/.local/state/avp/cmd.key``, created on first use
with mode 0600 (a directory 0700). Every node of the user's graphs, `avp swap-planner` and a custom planner that
uses :class:`CommandSigner` read the same file — the hand-over of a swapped-in planner is its access to that
file. What this does not stop: a process of the same user (it can read the file), and anything below the ROS
layer; a deployment needs SROS2 with a security-enabled DDS (docs/bad_input.md, "Security").
"""

from __future__ import annotations

import hashlib
import hmac
import os
import struct
from pathlib import Path

KEY_ENV = "AVP_CMD_KEY_FILE"
KEY_BYTES = 32
TAG_HEX = 32


def key_path() -> Path:
    """Where the command key lives (``$AVP_CMD_KEY_FILE`` or ``~/.local/state/avp/cmd.key``)."""
    env = os.environ.get(KEY_ENV, "")
    return Path(env) if env else Path.home() / ".local" / "state" / "avp" / "cmd.key"


def load_key(path: Path | None = None) -> bytes:
    """The command key, created (0600, in a 0700 directory) if there is none yet; OSError if unreadable."""
    p = path or key_path()
    if not p.exists():
        p.parent.mkdir(mode=0o700, parents=True, exist_ok=True)
        try:
            fd = os.open(p, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        except FileExistsError:  # another node created it meanwhile
            pass
        else:
            with os.fdopen(fd, "wb") as f:
                f.write(os.urandom(KEY_BYTES))
    key = p.read_bytes()
    if len(key) < 16:
        raise OSError(f"{p}: command key shorter than 16 bytes")
    return key


def _digest(key: bytes, frame: str, stamp_ns: int, v: float, om: float) -> str:
    payload = b"avp-cmd|" + frame.encode() + b"|" + struct.pack("<qdd", int(stamp_ns), float(v), float(om))
    return hmac.new(key, payload, hashlib.sha256).hexdigest()[:TAG_HEX]


def tagged_frame(key: bytes, frame: str, stamp_ns: int, v: float, om: float) -> str:
    """``header.frame_id`` of a command: ``<frame>#<tag>``."""
    return f"{frame}#{_digest(key, frame, stamp_ns, v, om)}"


def verify(key: bytes, frame_id: str, stamp_ns: int, v: float, om: float) -> bool:
    """True iff ``frame_id`` carries the tag of (stamp, v, ω) under ``key``."""
    frame, sep, tag = frame_id.rpartition("#")
    if not sep or len(tag) != TAG_HEX:
        return False
    return hmac.compare_digest(tag, _digest(key, frame, stamp_ns, v, om))


class CommandSigner:
    """Tags the ``cmd`` a planner publishes (``sign(msg)`` before ``publish``); used by every ego node."""

    def __init__(self, key: bytes | None = None):
        self.key = key if key is not None else load_key()

    def sign(self, msg, frame: str = "ego"):
        """Set ``msg.header.frame_id`` (a geometry_msgs/TwistStamped) to its tagged frame; returns ``msg``."""
        st = msg.header.stamp
        stamp_ns = int(st.sec) * 1_000_000_000 + int(st.nanosec)
        msg.header.frame_id = tagged_frame(self.key, frame, stamp_ns, msg.twist.linear.x, msg.twist.angular.z)
        return msg
