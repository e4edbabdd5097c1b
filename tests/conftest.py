"""Shared fixtures. Tests run inside the workspace environment (`make test` sources tools/env.sh)."""

from __future__ import annotations

import os
import random

import pytest

from avp_world.lot import load_bundled_lot

#: test processes that may run DDS test modules at once under pytest-xdist (make test): the others take the unit tests.
#: Four DDS modules at once on 2 cores (each test starts about five node processes) made real-time tests miss their
#: deadlines; two leave room for what they measure.
DDS_LANES = 2
#: rough wall seconds of each module's DDS tests under four test processes (pytest --durations of a fresh clone's
#: make test on a 2-core machine, at 5fe1932; test_fleet_dds.py less its fleet-transport test's bezier fleet, cut
#: since), to deal the modules to the lanes longest first; a module not listed counts 10 s a test
DDS_SECONDS = {"test_fleet_dds.py": 545, "test_operations.py": 395, "test_perception_nodes.py": 190,
               "test_demo_and_bag.py": 155, "test_security.py": 145, "test_experiment.py": 140, "test_teleop.py": 120,
               "test_dds_lockstep.py": 80, "test_flood.py": 75, "test_bad_input.py": 60, "test_bag_damage.py": 60,
               "test_nodes.py": 45, "test_foxglove.py": 20}


@pytest.hookimpl(tryfirst=True)  # before pytest-xdist's own hook reads the xdist_group marks
def pytest_collection_modifyitems(config, items):
    """Markers by what a test needs (pyproject.toml): ``dds`` for every test that uses :func:`ros_env` (it starts node
    processes, or talks over DDS itself), ``ray`` for the Ray backend's. ``-m "not dds and not ray"`` selects the
    unit tests; tools/stress_dds.py runs ``-m dds`` in a loop.

    With pytest-xdist's ``--dist loadgroup`` (make test) a module's other tests are one group (its module fixtures
    made once), and its DDS tests go to one of :data:`DDS_LANES` groups, each run by one process in turn: the modules
    are dealt longest first (:data:`DDS_SECONDS`) to the lane with the least so far."""
    dds_count: dict[str, int] = {}
    for item in items:
        if "ros_env" in getattr(item, "fixturenames", ()):
            item.add_marker(pytest.mark.dds)
            dds_count[item.path.name] = dds_count.get(item.path.name, 0) + 1
        if item.path.name == "test_ray_backend.py":
            item.add_marker(pytest.mark.ray)
    load, lanes = [0.0] * DDS_LANES, {}
    for name in sorted(dds_count, key=lambda n: (-DDS_SECONDS.get(n, 10 * dds_count[n]), n)):
        lane = load.index(min(load))
        lanes[name] = f"dds{lane}"
        load[lane] += DDS_SECONDS.get(name, 10 * dds_count[name])
    for item in items:
        dds = item.get_closest_marker("dds") is not None
        item.add_marker(pytest.mark.xdist_group(lanes[item.path.name] if dds else item.path.name))


@pytest.fixture(scope="session")
def paper_lot():
    return load_bundled_lot("paper_lot")


@pytest.fixture(scope="session")
def cmd_key_file(tmp_path_factory):
    """The message key of the tests' graphs (avp_common.msg_auth), not the user's own."""
    return str(tmp_path_factory.mktemp("cmd_key") / "cmd.key")


def _claim_test_domain():
    """(domain id, its lock file): a ROS domain no other test process and no running avp graph holds
    (avp_bringup.domain's lock files), searched from a random start so that a domain just left by a test (whose
    processes' discovery data may linger) is rarely the next one taken. Two test runs at once never share one."""
    from avp_bringup.domain import MAX_DOMAIN, _try_lock

    start = random.Random(os.getpid() * 7919 + random.randrange(1000)).randint(1, MAX_DOMAIN)
    for i in range(MAX_DOMAIN):
        d = (start - 1 + i) % MAX_DOMAIN + 1
        lock = _try_lock(d)
        if lock is not None:
            return d, lock
    raise RuntimeError(f"every ROS domain 1..{MAX_DOMAIN} is held")


@pytest.fixture()
def ros_env(cmd_key_file):
    """Environment for child ROS processes: a domain id of this test's own (held for the test, :func:`_claim_test_
    domain`), localhost discovery, the tests' command key (the test process signs with it too once the
    ``ros``-style fixtures copy this environment)."""
    env = dict(os.environ)
    env["AVP_CMD_KEY_FILE"] = cmd_key_file
    domain, lock = _claim_test_domain()
    env["ROS_DOMAIN_ID"] = str(domain)
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    env["PYTHONUNBUFFERED"] = "1"
    yield env
    lock.close()  # releases the flock


@pytest.fixture()
def ros_unbuffered(ros_env, monkeypatch):
    """This process joins the test's ROS domain (rclpy initialised, shut down after) and its child nodes log
    unbuffered (their log files are read by the test); yields the children's environment."""
    import rclpy

    env = {**ros_env, "RCUTILS_LOGGING_BUFFERED_STREAM": "0"}
    for k, v in env.items():
        monkeypatch.setenv(k, v)
    rclpy.init()
    yield env
    rclpy.try_shutdown()
