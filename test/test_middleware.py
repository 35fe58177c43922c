"""The middleware defaults of this package's processes
(flock_swarm.nodes.spin.middleware_defaults): rmw_fastrtps's synchronous publication unless
the environment names a mode, and runs that equal ``sim`` bit for bit in either mode (the
mode changes who sends a message, never what).
"""

import os

import pytest

from flock_swarm.nodes.spin import PUBLICATION_MODE, middleware_defaults
from flock_swarm.testing import Swarm, assert_matches_sim

pytestmark = pytest.mark.ros

VARIABLE, DEFAULT = PUBLICATION_MODE
#: A few steps of a few agents, in one process and with agents in processes of their own.
SMALL = ['n_agents=4', 'informed.count=2', 'duration=0.2']


def test_the_defaults_fill_only_what_the_environment_leaves_unset():
    env = {}
    middleware_defaults(env)
    assert env == {VARIABLE: 'SYNCHRONOUS'} and DEFAULT == 'SYNCHRONOUS'
    env = {VARIABLE: 'ASYNCHRONOUS'}
    middleware_defaults(env)
    assert env == {VARIABLE: 'ASYNCHRONOUS'}


def test_an_in_process_swarm_sets_the_mode_before_its_context(tmp_path, ros_domain,
                                                              monkeypatch):
    monkeypatch.delenv(VARIABLE, raising=False)
    with Swarm('demo', tmp_path / 'run', ['n_agents=2', 'informed.count=1', 'duration=0.04'],
               domain_id=ros_domain) as swarm:
        assert os.environ[VARIABLE] == 'SYNCHRONOUS'
        swarm.spin_to_end(60)
        assert swarm.world.done


@pytest.mark.parametrize('mode', ['ASYNCHRONOUS', 'SYNCHRONOUS'])
@pytest.mark.parametrize('layout', [{}, {'processes': True}], ids=['one process', 'processes'])
def test_a_lockstep_run_matches_sim_in_either_publication_mode(tmp_path, ros_domain,
                                                               monkeypatch, mode, layout):
    monkeypatch.setenv(VARIABLE, mode)
    run = assert_matches_sim('demo', tmp_path / 'run', SMALL, domain_id=ros_domain, atol=0,
                             timeout=120, **layout)
    assert run.summary['n_agents'] == 4
    assert os.environ[VARIABLE] == mode   # the user's choice stands
