"""The V2V node between the egos of a fleet (avp_planner.v2v_node, on avp_planner.lockstep_relay) over DDS, in one
process: a hand-driven simulator and two planners feed it, a reader takes what it answers.

In lock-step it holds the beacons of step k until every ego it answered at step k-1 has decided that step. In real
time it answers at once: a real-time planner skips the steps it falls behind on, so the decision waited for may never
come — and it must learn that from the simulator's episode status even when its ``lockstep`` parameter says
otherwise (``avp demo --realtime --egos 2`` once started it with ``lockstep:=true``: each ego then waited for the
other's decision of the step before, and a skipped step left the next one's beacons held until the planner's
``stale_input_timeout``).
"""

from __future__ import annotations

import time

import pytest

rclpy = pytest.importorskip("rclpy")

EPISODE = 7


def _drive(lock_step: bool):
    """The V2V node (``lockstep:=true``) with a simulator of mode ``lock_step``: steps 0 and 1 of two egos, where ego 1
    never decides step 0. Returns ({ego: {step: beacons}} heard by 1 s after observation 1, a function that sends ego
    1's decision of step 0 and returns the same dict 1 s later)."""
    from geometry_msgs.msg import Pose2D
    from rclpy.executors import SingleThreadedExecutor

    from avp_common.msg_auth import Authenticator, with_episode
    from avp_common.qos import STATUS, STEP
    from avp_msgs.msg import EgoBeaconArray, EpisodeStatus, Observation, PlannerDecision
    from avp_planner.v2v_node import V2VNode

    v2v = V2VNode()
    sim = rclpy.create_node("hand_sim", namespace="/avp")
    auth = Authenticator(sim)
    obs_pub = {i: auth.publisher(Observation, f"ego{i}/observation", STEP, ego=i) for i in (0, 1)}
    dec_pub = {i: auth.publisher(PlannerDecision, f"ego{i}/decision", STEP, ego=i) for i in (0, 1)}
    status_pub = {i: sim.create_publisher(EpisodeStatus, f"ego{i}/episode_status", STATUS) for i in (0, 1)}
    heard: dict[int, dict[int, list]] = {0: {}, 1: {}}
    for i in (0, 1):
        sim.create_subscription(EgoBeaconArray, f"ego{i}/v2v/beacons",
                                lambda m, i=i: heard[i].setdefault(int(m.step), list(m.beacons)), STEP)
    ex = SingleThreadedExecutor()
    ex.add_node(v2v)
    ex.add_node(sim)

    def spin(seconds: float, until=lambda: False) -> None:
        t0 = time.monotonic()
        while time.monotonic() - t0 < seconds and not until():
            ex.spin_once(timeout_sec=0.02)

    def frame():
        return with_episode("map", EPISODE)

    def observe(step: int) -> None:
        for i in (0, 1):
            status_pub[i].publish(EpisodeStatus(step=step, state=EpisodeStatus.STATE_RUNNING, lock_step=lock_step))
            msg = Observation(step=step, dt=0.1, ego_pose=Pose2D(x=10.0 * i + step, y=2.0, theta=0.5))
            msg.header.stamp.nanosec = 100_000_000 * step
            msg.header.frame_id = frame()
            obs_pub[i].publish(msg)

    def decide(i: int, step: int) -> None:
        msg = PlannerDecision(step=step, waiting=True, announced=[Pose2D(x=1.0, y=2.0, theta=0.0)])
        msg.header.frame_id = frame()
        dec_pub[i].publish(msg)

    # every reader matched (the V2V node's subscriptions and ours) before anything is sent
    spin(20.0, lambda: all(p.get_subscription_count() >= 1 for p in (*obs_pub.values(), *dec_pub.values()))
         and all(v2v.pub[i].get_subscription_count() >= 1 for i in (0, 1)))
    observe(0)
    spin(10.0, lambda: all(0 in heard[i] for i in (0, 1)))
    assert all(heard[i].get(0) == [] for i in (0, 1)), heard  # step 0: nobody has decided anything yet
    decide(0, 0)  # ego 0 decides step 0; ego 1 falls behind and skips it
    spin(20.0, lambda: 0 in v2v.decided.get(0, {}))  # the decision is in before observation 1 goes out
    observe(1)
    # real time: answered at once (waited for generously); lock-step: a second in which it must not come
    spin(1.0 if lock_step else 20.0, lambda: all(1 in heard[i] for i in (0, 1)))

    def late_decision() -> dict:
        decide(1, 0)
        spin(20.0, lambda: all(1 in heard[i] for i in (0, 1)))
        return heard

    return heard, late_decision, (v2v, sim)


@pytest.mark.parametrize("lock_step", [False, True])
def test_v2v_holds_a_step_for_the_decisions_before_only_in_lock_step(ros_env, monkeypatch, lock_step):
    for k, v in ros_env.items():
        monkeypatch.setenv(k, v)
    rclpy.init(args=["--ros-args", "-r", "__ns:=/avp", "-p", "egos:=0,1", "-p", "min_subscribers:=1",
                     "-p", "lockstep:=true"])
    nodes = ()
    try:
        heard, late_decision, nodes = _drive(lock_step)
        if lock_step:  # held: ego 1 has not decided step 0
            assert 1 not in heard[0] and 1 not in heard[1], heard
            heard = late_decision()
        # answered, each ego hearing the egos before it as they decided step 0, at the pose they decided it on
        assert heard[0][1] == [], heard
        (b,) = heard[1][1]
        assert (b.ego, b.waiting, b.pose.x, b.pose.y, len(b.path)) == (0, True, 0.0, 2.0, 1), b
    finally:
        for n in nodes:
            n.destroy_node()
        rclpy.try_shutdown()


@pytest.mark.parametrize(("argv", "lockstep"), [(["demo", "--egos", "2"], True),
                                                (["demo", "--egos", "2", "--realtime"], False),
                                                (["demo", "--egos", "3", "--drive"], False)])
def test_the_demos_fleet_relays_run_in_the_simulators_mode(argv, lockstep):
    """The simulator's mode reaches the V2V node: a real-time demo's relay never waits for a decision."""
    from avp_bringup.cli import build_parser
    from avp_bringup.demo import _demo_nodes

    nodes = _demo_nodes(build_parser().parse_args(argv))
    v2v = next(n for n in nodes if getattr(n, "name", "") == "avp_v2v")
    assert v2v.extra_params["lockstep"] is lockstep
    assert nodes[0].extra_params["mode"] == ("lockstep" if lockstep else "realtime")
