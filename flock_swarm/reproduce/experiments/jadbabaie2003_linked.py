"""Jadbabaie, Lin, Morse 2003, Theorem 4 on a set-up of ours in which its premise holds (the
followers start linked to the leader)."""

from flock_swarm.reproduce.experiment import SetUp
from flock_swarm.reproduce.experiments.jadbabaie2003_leader import JLM03, Leader


class Linked(Leader):
    """Jadbabaie 2003 Theorem 4 with its premise met: the analysis, table and figure of
    :class:`~flock_swarm.reproduce.experiments.jadbabaie2003_leader.Leader`."""

    key = 'jadbabaie2003_linked'
    title = 'Jadbabaie 2003, Theorem 4 with its premise met'
    paper = JLM03
    claim = (
        'Theorem 4 as above, on a set-up of ours in which its premise holds: the followers '
        'start linked to the leader (a 4 m x 4 m box and r = 6 instead of 6 m x 6 m and '
        'r = 3), so that they agree on a heading before the constant speed carries them out '
        'of its reach. Then **every follower converges to theta_0**.')
    order = 510.0
    ros = None
    ros_quick = ()
    setups = (SetUp('reproduce_jadbabaie2003_linked', 'premise holding (jadbabaie2003_linked)'),)


EXPERIMENT = Linked()
