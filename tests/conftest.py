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


@pytest.hookimpl(tryfirst=True)  # before pytest-xdist's own hook reads the xdist_group marks
def pytest_collection_modifyitems(config, items):
    """Markers by what a test needs (pyproject.toml): ``dds`` for every test that uses :func:`ros_env` (it starts node
    processes, or talks over DDS itself), ``ray`` for the Ray backend's. ``-m "not dds and not ray"`` selects the
    unit tests; tools/stress_dds.py runs ``-m dds`` in a loop.

    With pytest-xdist's ``--dist loadgroup`` (make test) every module is one group (its module fixtures made once),
    and the modules with a DDS test are dealt to :data:`DDS_LANES` groups, each run by one process in turn."""
    dds_modules: list[str] = []
    for item in items:
        if "ros_env" in getattr(item, "fixturenames", ()):
            item.add_marker(pytest.mark.dds)
            if item.path.name not in dds_modules:
                dds_modules.append(item.path.name)
        if item.path.name == "test_ray_backend.py":
            item.add_marker(pytest.mark.ray)
    lanes = {name: f"dds{i % DDS_LANES}" for i, name in enumerate(sorted(dds_modules))}
    for item in items:
        item.add_marker(pytest.mark.xdist_group(lanes.get(item.path.name, item.path.name)))


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
