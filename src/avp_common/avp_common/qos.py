"""QoS profiles of the AVP graph (REP-2003 and the lock-step design in docs/architecture.md)."""

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

#: Static data a late joiner must still get (lot map): reliable + transient_local, depth 1.
LATCHED = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
#: Per-step data in lock-step (observations, beliefs, predictions, commands): every message matters.
STEP = QoSProfile(depth=10, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE,
                  durability=DurabilityPolicy.VOLATILE)
#: The reader side of per-step inputs. A publisher gone wild at 1 kHz on the topic (issue #20 item 2) would push the
#: real message of a step out of a 10-deep reader queue within 10 ms of the node being busy; 1000 holds a second
#: of such a flood (bounded: about 4 MB of observations). Writers keep STEP's depth.
STEP_INPUT = QoSProfile(depth=1000, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.VOLATILE)
#: A node answers a copy of a step it has answered (a re-sent observation) at most once per this many seconds,
#: so a flood of copies of a tagged message does not become a flood of answers.
RESEND_ANSWER_INTERVAL = 1.0
#: Ground truth (debug/ground_truth), the source of every metric: a monitor or recorder that falls behind for a
#: while (a loaded machine) must still get every step, so the writer keeps 30 s of them (KEEP_LAST drops unacked
#: samples once its history is full).
GROUND_TRUTH = QoSProfile(depth=300, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE,
                          durability=DurabilityPolicy.VOLATILE)
#: Debug/visualisation streams: latest only.
DEBUG = QoSProfile(depth=2, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE,
                   durability=DurabilityPolicy.VOLATILE)
#: Episode status: latched so a monitor that joins late sees the last one.
STATUS = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE,
                    durability=DurabilityPolicy.TRANSIENT_LOCAL)
