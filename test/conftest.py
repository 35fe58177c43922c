"""Shared fixtures: unique ROS domain ids so concurrent runs never see each other."""

import itertools
import os
import subprocess
import time

import pytest

_counter = itertools.count()

# DDS discovery stays on this machine unless the caller asked otherwise (scripts/env.sh sets
# the same default), so a test run never talks to, or hears from, another host.
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')


def _unique_domain() -> int:
    """Return a ROS domain id unique within this pytest process, in [1, 200].

    Ids are spread over the range by process id, so two pytest processes on one machine are
    unlikely to collide.
    """
    return 1 + (os.getpid() * 37 + next(_counter)) % 200


@pytest.fixture
def ros_domain() -> int:
    """Return a ROS domain id unique to this test within this pytest process.

    Ids are spread over [1, 200] by process id, so two pytest processes on one machine are
    unlikely to collide; discovery is limited to localhost by scripts/env.sh (and above).
    """
    return _unique_domain()


@pytest.fixture
def ros_context(ros_domain):
    """Return an initialised ``rclpy`` context of its own on the test's domain id."""
    import rclpy
    from rclpy.context import Context
    context = Context()
    rclpy.init(context=context, domain_id=ros_domain)
    yield context
    rclpy.try_shutdown(context=context)


@pytest.fixture
def other_ros_domain(ros_domain) -> int:
    """Return a second domain id for the same test, different from :func:`ros_domain`'s."""
    return _unique_domain()


def start_nodes(scenario, domain: int, out, agents: int, world_args=(),
                world_stderr=subprocess.DEVNULL):
    """Start the leader, ``agents`` agent processes and the world (the ros2 run executables).

    :return: ``(others, world)``: the leader's and agents' processes, and the world's.
    """
    from flock_swarm.runner import executable
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain))
    ros_args = ['--ros-args', '-p', f'scenario:={scenario}']
    quiet = {'env': env, 'stdout': subprocess.DEVNULL, 'stderr': subprocess.DEVNULL}
    others = [subprocess.Popen(executable('leader') + ros_args, **quiet)]
    others += [subprocess.Popen(executable('agent') + ros_args + ['-p', f'agent_id:={i}'],
                                **quiet) for i in range(agents)]
    world = subprocess.Popen(executable('world') + ros_args + ['-p', f'out_dir:={out}',
                                                               *world_args],
                             env=env, stdout=subprocess.DEVNULL, stderr=world_stderr,
                             text=True)
    return others, world


def wait_for(condition, timeout: float, what: str) -> None:
    """Poll ``condition`` until it holds; fail after ``timeout`` seconds."""
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            pytest.fail(f'timed out after {timeout:g} s waiting for {what}')
        time.sleep(0.05)
