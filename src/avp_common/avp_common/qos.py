"""QoS profiles of the AVP graph (REP-2003 and the lock-step design in docs/architecture.md)."""

from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy


def _reliable(depth: int, durability: DurabilityPolicy) -> QoSProfile:
    """Reliable, keep-last ``depth`` (every profile of the graph is reliable; they differ in depth and durability)."""
    return QoSProfile(depth=depth, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE,
                      durability=durability)


#: Static data a late joiner must still get (lot map): reliable + transient_local, depth 1.
LATCHED = _reliable(1, DurabilityPolicy.TRANSIENT_LOCAL)
#: Per-step data in lock-step (observations, beliefs, predictions, commands): every message matters.
STEP = _reliable(10, DurabilityPolicy.VOLATILE)
#: The reader side of per-step inputs. A publisher gone wild at 1 kHz on the topic (docs/bad_input.md row 48)
#: would push the real message of a step out of a 10-deep reader queue within 10 ms of the node being busy; 1000
#: holds a second of such a flood (bounded: about 4 MB of observations). Writers keep STEP's depth.
STEP_INPUT = _reliable(1000, DurabilityPolicy.VOLATILE)
#: A node answers a copy of a step it has answered (a re-sent observation) at most once per this many seconds,
#: so a flood of copies of a tagged message does not become a flood of answers.
RESEND_ANSWER_INTERVAL = 1.0
#: Ground truth (debug/ground_truth), the source of every metric: a monitor or recorder that falls behind for a
#: while (a loaded machine) must still get every step, so the writer keeps 30 s of them (KEEP_LAST drops unacked
#: samples once its history is full).
GROUND_TRUTH = _reliable(300, DurabilityPolicy.VOLATILE)
#: Debug/visualisation streams: latest only.
DEBUG = _reliable(2, DurabilityPolicy.VOLATILE)
#: Episode status: latched so a monitor that joins late sees the last one.
STATUS = _reliable(1, DurabilityPolicy.TRANSIENT_LOCAL)


def reader_qos(latched: bool, depth: int) -> QoSProfile:
    """A sink's reader of a graph topic (recorder, viewers): :data:`LATCHED` for a latched topic, else reliable,
    volatile, keep-last ``depth``."""
    return LATCHED if latched else _reliable(depth, DurabilityPolicy.VOLATILE)


#: QoS event handlers of the graph's own readers and writers: none (``event_callbacks=QUIET_READER`` /
#: ``QUIET_WRITER``). rclpy gives every endpoint two by default (incompatible QoS, incompatible type: each logs a
#: warning), and its executor walks each of them in Python, and Fast DDS attaches each to its wait set, for every
#: message a process takes: with the demo's recorder and monitor (about 45 readers) that was two thirds of the
#: process's CPU, in a live fleet more than a fifth of all the CPU the graph used (docs/benchmarks.md, "QoS event
#: handlers"). What the warnings told is still told: the graph's endpoints agree by construction (these profiles);
#: a foreign endpoint of incompatible QoS gets rclpy's warning on its own side, a foreign publisher's messages are
#: not taken anyway (avp_common.msg_auth), and the recorder (``avp record``, ``avp demo``) names a reader that has
#: matched no writer the graph shows for 10 s (avp_bag.recorder.BagRecorder.warn_unmatched_after). A writer of
#: another type on a topic (a ``Twist`` where a ``TwistStamped`` is read) matches nothing and gets no warning from
#: Fast DDS even with the handlers (tried: neither side logs one); where a person's tool connects, a driven car's
#: ``cmd_vel``, the simulator names such a writer itself (avp_sim.ego_channels.DriverTypeCheck).
QUIET_READER = SubscriptionEventCallbacks(use_default_callbacks=False)
QUIET_WRITER = PublisherEventCallbacks(use_default_callbacks=False)
