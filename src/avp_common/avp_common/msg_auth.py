"""Authenticated messages between the graph's nodes (docs/bad_input.md rows 34 and 41): only a holder of the user's key
can feed the ego pipeline or steer the ego.

The Fast DDS of the ROS 2 wheels has no DDS security (no SROS2), and Jazzy's rclpy does not tell a subscriber
which writer sent a message, so a node cannot tell its configured publisher's message from another process's by
origin. Instead every message of the pipeline carries a tag in ``header.frame_id = "<frame>#<episode><tag>"``: the
episode id (16 hex digits: the simulator's episode the message belongs to, 0 for none) and the first 32
hex digits of HMAC-SHA256(key, the bytes sent, with the tag's place filled with '0's). The tag covers the episode
id, so a copy of a message stays a message of its episode: a replayed step 0 of the running episode is a copy, not a
new episode, and a message of an earlier episode is dropped (:mod:`avp_common.step_answers`). The sender publishes
the serialised bytes it tagged; the receiver subscribes raw, checks the bytes it got, then deserialises. A node with
``auth_inputs: true`` drops an input whose tag does not verify and names the publishers on that topic (once per new
one, then a count at most once a second). A copy of a message is the sender's own (same content); a changed one
cannot be forged without the key.

Tagged: ``lot_map`` and ``observation`` (simulator), ``beliefs``, ``intentions``, ``ego_intention`` (belief
node), ``predictions`` (prediction node), ``decision`` (planner), ``reserved/observation`` (the reservation node
of several egos), ``cmd`` (every ego node; a custom planner wraps its publisher with
:meth:`Authenticator.publisher`). The key: 32 random bytes in ``$AVP_CMD_KEY_FILE``, default
``~/.local/state/avp/cmd.key``, created on first use with mode 0600 in a 0700 directory; every node of the
user's graphs, `avp swap-planner`'s planners and custom planners read the same file — a swapped-in planner's
hand-over is its access to it.

Several egos (docs/world.md, "Several egos"): ego i's pipeline runs in namespace ``/avp/ego<i>``. A node there tags
what it publishes with ego i's key, HMAC-SHA256(key, "ego<i>") (:func:`scoped_key`), and a message on a topic under
``/ego<i>/`` verifies only with ego i's key; every other topic (``/avp/lot_map``) keeps the key itself. So ego 1's
planner cannot steer ego 0 — its command on ``/avp/ego0/cmd``, a copy or a misconfigured remap, carries ego 1's tag —
and one graph's egos cannot feed each other's pipelines. With one ego (namespace ``/avp``) nothing changes.

Not stopped: a process of the same user (it can read the file), readers of any topic (nothing is encrypted); a
deployment needs SROS2 with a security-enabled DDS (docs/bad_input.md).
"""

from __future__ import annotations

import hashlib
import hmac
import os
import re
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from rclpy.serialization import serialize_message

from avp_common.drain import draining_subscription
from avp_common.qos import QUIET_WRITER
from avp_common.received import deserialize

KEY_ENV = "AVP_CMD_KEY_FILE"
KEY_BYTES = 32
TAG_HEX = 32
EPISODE_HEX = 16
#: the largest input a node reads (docs/bad_input.md row 52): a DLP-lot observation is ~0.2 MB; anything larger
#: is dropped before its tag is even checked
MAX_INPUT_BYTES = 16 * 2**20


def with_episode(frame: str, episode: int) -> str:
    """``frame`` (any tag stripped) marked as belonging to ``episode``: sign() keeps the mark and tags it."""
    return f"{frame.partition('#')[0]}#{int(episode) & (2**64 - 1):0{EPISODE_HEX}x}"


def episode_of(frame_id: str) -> int:
    """The episode id a (tagged) ``header.frame_id`` carries; 0 when it carries none."""
    mark = frame_id.partition("#")[2][:EPISODE_HEX]
    try:
        return int(mark, 16) if len(mark) == EPISODE_HEX else 0
    except ValueError:
        return 0


def key_path() -> Path:
    """Where the key lives (``$AVP_CMD_KEY_FILE`` or ``~/.local/state/avp/cmd.key``)."""
    env = os.environ.get(KEY_ENV, "")
    return Path(env) if env else Path.home() / ".local" / "state" / "avp" / "cmd.key"


def load_key(path: Path | None = None) -> bytes:
    """The key, created (0600, in a 0700 directory) if there is none yet; OSError if unreadable or short.

    Nodes started together race to create it: the key is written to a file of this process's own and then linked
    to ``path`` (atomic, refused when ``path`` exists), so a node never reads a key file that another is still
    writing, and every node ends up with the one key that was linked first."""
    p = path or key_path()
    if not p.exists():
        p.parent.mkdir(mode=0o700, parents=True, exist_ok=True)
        tmp = p.with_name(f".{p.name}.{os.getpid()}.{os.urandom(4).hex()}")
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        try:
            with os.fdopen(fd, "wb") as f:
                f.write(os.urandom(KEY_BYTES))
            os.link(tmp, p)
        except FileExistsError:  # another node created it meanwhile: take that one
            pass
        finally:
            tmp.unlink(missing_ok=True)
    key = p.read_bytes()
    if len(key) < 16:
        raise OSError(f"{p}: message key shorter than 16 bytes")
    return key


_PLACEHOLDER = b"0" * TAG_HEX
_FRAME_LEN_AT = 12  # CDR: 4-byte encapsulation header, header.stamp (int32 sec, uint32 nanosec), frame_id length


_EGO_SCOPE = re.compile(r"(?:^|/)(ego\d+)(?:/|$)")


def ego_scope(name: str) -> str | None:
    """``"ego<i>"`` when the namespace or topic ``name`` lies under an ego's namespace (``/avp/ego1/cmd``), else
    None."""
    m = _EGO_SCOPE.search(name)
    return m.group(1) if m else None


def scoped_key(key: bytes, scope: str | None) -> bytes:
    """The key of ``scope`` (an ego's, :func:`ego_scope`): HMAC-SHA256(key, scope); ``key`` itself for None."""
    return key if scope is None else hmac.new(key, scope.encode(), hashlib.sha256).digest()


def _frame_span(data: bytes | bytearray) -> tuple[int, int] | None:
    """(start, end) of the tag's 32 characters at the end of ``header.frame_id`` in a serialised message whose
    first field is its ``header``; None if the frame carries no tag slot (``#``, 16 episode and 32 tag
    characters)."""
    if len(data) < _FRAME_LEN_AT + 4:
        return None
    order = "little" if data[1] & 1 else "big"  # CDR_LE / CDR_BE encapsulation
    n = int.from_bytes(data[_FRAME_LEN_AT:_FRAME_LEN_AT + 4], order)  # characters + the terminating NUL
    end = _FRAME_LEN_AT + 4 + n - 1
    start = end - TAG_HEX
    mark = start - EPISODE_HEX - 1
    if n < TAG_HEX + EPISODE_HEX + 2 or end > len(data) or data[mark:mark + 1] != b"#":
        return None
    return start, end


def sign(key: bytes, msg: Any, episode: int | None = None) -> bytes:
    """``msg`` (a message whose first field is its ``header``) serialised with its tag in ``header.frame_id``:
    publish these bytes (``Publisher.publish`` takes them). The tag covers the exact bytes sent, so the receiver
    checks what it got (CDR padding is not deterministic from one serialisation to the next). ``episode``: the
    episode id to carry (default: the one ``header.frame_id`` is marked with, :func:`with_episode`, else 0)."""
    ep = episode_of(msg.header.frame_id) if episode is None else episode
    base = with_episode(msg.header.frame_id, ep)
    msg.header.frame_id = f"{base}{_PLACEHOLDER.decode()}"
    data = bytearray(serialize_message(msg))
    # DDS sends a payload padded to a multiple of 4 bytes: pad it here, so that the receiver checks the bytes tagged
    # (a message ending in a string, avp_msgs/PlannerDecision's reason, would otherwise arrive with 1-3 bytes more)
    data += b"\0" * (-len(data) % 4)
    span = _frame_span(data)
    assert span is not None
    tag = hmac.new(key, bytes(data), hashlib.sha256).hexdigest()[:TAG_HEX].encode()
    data[span[0]:span[1]] = tag
    msg.header.frame_id = f"{base}{tag.decode()}"
    return bytes(data)


def verify(key: bytes, data: bytes) -> bool:
    """True iff the serialised message ``data`` carries its tag under ``key``."""
    span = _frame_span(data)
    if span is None:
        return False
    tag = bytes(data[span[0]:span[1]])
    blank = bytearray(data)
    blank[span[0]:span[1]] = _PLACEHOLDER
    return hmac.compare_digest(tag, hmac.new(key, bytes(blank), hashlib.sha256).hexdigest()[:TAG_HEX].encode())


class _SigningPublisher:
    """A publisher that tags what it publishes; everything else is the rclpy publisher's."""

    def __init__(self, pub, key: bytes):
        self._pub, self._key = pub, key

    def publish(self, msg) -> None:
        self._pub.publish(sign(self._key, msg))

    def __getattr__(self, name: str):
        return getattr(self._pub, name)


class Authenticator:
    """Per node: tags its outputs, checks its inputs (``check_inputs``), reports what it drops."""

    def __init__(self, node, check_inputs: bool = True, key: bytes | None = None):
        self.node = node
        self.master = key if key is not None else load_key()
        #: what this node signs with: its ego's key in /avp/ego<i>, else the key itself (module docstring)
        self.key = scoped_key(self.master, ego_scope(node.get_namespace()))
        self.check_inputs = bool(check_inputs)
        self.dropped: dict[tuple[str, str], int] = {}  # (topic, reason) -> count
        self._last_log: dict[tuple[str, str], float] = {}
        self._publishers: dict[str, tuple[float, set[str]]] = {}
        self._reported: dict[str, set[str]] = {}

    def publisher(self, msg_type, topic: str, qos, *, ego: int | None = None):
        """A publisher that tags with this node's key, or with ego ``ego``'s (the simulator's per-ego outputs)."""
        key = self.key if ego is None else scoped_key(self.master, f"ego{int(ego)}")
        return _SigningPublisher(self.node.create_publisher(msg_type, topic, qos, event_callbacks=QUIET_WRITER), key)

    def key_for(self, topic: str) -> bytes:
        """The key an input on the (resolved) ``topic`` must carry: its ego's under /ego<i>/, else the key itself."""
        return scoped_key(self.master, ego_scope(topic))

    def subscription(self, msg_type, topic: str, callback, qos, *, with_info: bool = False,
                     read: Callable[[bytes], Any] | None = None):
        """A subscription that checks the tag on the received bytes, then deserialises and calls ``callback``
        (``callback(msg, info)`` with ``with_info``: the DDS message info, e.g. its source timestamp). ``read``: what
        makes the callback's argument of the checked bytes instead (a reader of a few fields,
        :func:`avp_common.received.observation_head`); ``msg_type`` stays the topic's type."""
        holder: dict = {}

        def checked(data: bytes, info=None) -> None:
            if len(data) > MAX_INPUT_BYTES:
                self._report(holder["sub"].topic_name, f"larger than {MAX_INPUT_BYTES} bytes, dropped unread")
                return
            if self.check_inputs and not verify(holder["key"], data):
                self._report(holder["sub"].topic_name)
                return
            # one message per payload in a component container (avp_common.received)
            msg = deserialize(data, msg_type) if read is None else read(data)
            callback(msg, info) if with_info else callback(msg)

        # bursts taken in one executor round: a flood costs a wait-set rebuild per batch, not per message
        holder["sub"] = draining_subscription(self.node, msg_type, topic, checked, qos, with_info=with_info)
        holder["key"] = self.key_for(holder["sub"].topic_name)
        return holder["sub"]

    def _report(self, topic: str, why: str = "unauthenticated") -> None:
        """One line when a new publisher shows up on ``topic`` while its messages fail, else one a second per
        reason (``why``: a flood of one kind must not hide the other)."""
        n = self.dropped[(topic, why)] = self.dropped.get((topic, why), 0) + 1
        now = time.monotonic()
        seen_at, pubs = self._publishers.get(topic, (-1e9, set()))
        if now - seen_at >= 1.0:
            infos = self.node.get_publishers_info_by_topic(topic)
            pubs = {f"{i.node_namespace.rstrip('/')}/{i.node_name}" for i in infos}
            self._publishers[topic] = (now, pubs)
        reported = self._reported.setdefault(topic, set())
        new = sorted(pubs - reported)
        if new or now - self._last_log.get((topic, why), -1e9) >= 1.0:
            reported |= set(new)
            self._last_log[(topic, why)] = now
            self.node.get_logger().error(
                f"{topic}: {n} {why} message(s) dropped so far (auth_inputs; docs/bad_input.md); "
                f"publishers on it: {sorted(pubs)}" + (f"; new: {new}" if new else ""))
