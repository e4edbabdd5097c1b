"""QoS profiles of the AVP graph (REP-2003 and the lock-step design in docs/architecture.md)."""

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

#: Static data a late joiner must still get (lot map): reliable + transient_local, depth 1.
LATCHED = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
#: Per-step data in lock-step (observations, beliefs, predictions, commands): every message matters.
STEP = QoSProfile(depth=10, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE,
                  durability=DurabilityPolicy.VOLATILE)
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
