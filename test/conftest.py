"""Fixtures specific to this repository's tests.

The generic ones (``ros_domain``, ``other_ros_domain``, ``flock_swarm_run``,
``in_process_swarm``) and the wait helpers come from :mod:`flock_swarm.testing`, the pytest
plugin every user's tests get too.
"""

import os
import subprocess

# DDS discovery stays on this machine unless the caller asked otherwise (scripts/env.sh sets
# the same default), so a test run never talks to, or hears from, another host, also in the
# tests that start processes without a ros_domain fixture.
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')


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
