"""Shared fixtures. Tests run inside the workspace environment (`make test` sources tools/env.sh)."""

from __future__ import annotations

import os
import random

import pytest

from avp_world.lot import load_bundled_lot


@pytest.fixture(scope="session")
def paper_lot():
    return load_bundled_lot("paper_lot")


@pytest.fixture()
def ros_env():
    """Environment for child ROS processes: a domain id of this test's own, localhost discovery."""
    env = dict(os.environ)
    env["ROS_DOMAIN_ID"] = str(random.Random(os.getpid() * 7919 + random.randrange(1000)).randint(1, 101))
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    env["PYTHONUNBUFFERED"] = "1"
    return env
