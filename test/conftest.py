"""Shared fixtures: unique ROS domain ids so concurrent runs never see each other."""

import itertools
import os

import pytest

_counter = itertools.count()


@pytest.fixture
def ros_domain() -> int:
    """Return a ROS domain id unique to this test within this pytest process.

    Ids are spread over [1, 200] by process id, so two pytest processes on one machine are
    unlikely to collide; discovery is limited to localhost by scripts/env.sh.
    """
    return 1 + (os.getpid() * 37 + next(_counter)) % 200
