"""The network statistics as a user meets them outside ROS: ``sweep`` varies every
``network.*`` key and collects the statistics, ``sim --plots`` draws ``network.png``."""

import csv
import json

import numpy as np
import pytest

from flock_swarm.cli.sim import main as sim_main
from flock_swarm.cli.sweep import main as sweep_main
from flock_swarm.study.spec import parse_spec, plan_runs

#: A small dense swarm: every pair within the radius, so every agent has neighbours.
SMALL = {'n_agents': 8, 'informed.count': 3, 'duration': 0.4,
         'initial.position_box': [[0, 8], [0, 8]]}
#: Every key of the section (a delay's law as a whole mapping), each with two values a sweep
#: takes, what the scenario holds for the second (``dt`` 0.02 s: times in steps), and the
#: fixed values the axis needs around it (a Gilbert-Elliott channel).
GE = {'network.loss': {'model': 'gilbert_elliott', 'p_good_bad': 0.1, 'p_bad_good': 0.5}}
AXES = [
    ('network.delay', [0.02, 0.1], lambda n: n.agents.delay.high == 5, {}),
    ('network.delay', [{'law': 'uniform', 'min': 0.02, 'max': 0.06},
                       {'law': 'geometric', 'mean': 0.04, 'max': 0.1}],
     lambda n: (n.agents.delay.law, n.agents.delay.high) == ('geometric', 5), {}),
    ('network.loss', [0.1, 0.3], lambda n: n.agents.loss.p == 0.3, {}),
    ('network.loss.p_good_bad', [0.1, 0.2], lambda n: n.agents.loss.p_good_bad == 0.2, GE),
    ('network.loss.p_bad_good', [0.5, 0.6], lambda n: n.agents.loss.p_bad_good == 0.6, GE),
    ('network.loss.loss_good', [0.0, 0.05], lambda n: n.agents.loss.loss_good == 0.05, GE),
    ('network.loss.loss_bad', [1.0, 0.8], lambda n: n.agents.loss.loss_bad == 0.8, GE),
    ('network.noise.position', [0.0, 0.1], lambda n: n.agents.noise_position == 0.1, {}),
    ('network.noise.velocity', [0.0, 0.1], lambda n: n.agents.noise_velocity == 0.1, {}),
    ('network.period', [1, 3], lambda n: n.agents.period == 3, {}),
    ('network.leader.delay', [0.0, 0.04], lambda n: n.leader.delay.high == 2, {}),
    ('network.leader.loss', [0.0, 0.2], lambda n: n.leader.loss.p == 0.2, {}),
    ('network.leader.noise.position', [0.0, 0.1], lambda n: n.leader.noise_position == 0.1,
     {}),
    ('network.leader.period', [1, 2], lambda n: n.leader.period == 2, {}),
    ('network.model', ['communication', 'input'], lambda n: n.model == 'input', {}),
    ('network.max_age', [0.1, 0.2], lambda n: n.max_age == 10, {}),
]


@pytest.mark.parametrize('key, values, second, around', AXES,
                         ids=[f'{a[0]}-{n}' for n, a in enumerate(AXES)])
def test_a_sweep_varies_every_network_key(key, values, second, around):
    # The set gives nothing the axis sets (it would be replaced: refused, test_sweep), so
    # the delay axis runs without the set's delay and the Gilbert-Elliott chain's own axes
    # without their value in the set.
    fixed = {**SMALL, **({} if key == 'network.delay' else {'network.delay': 0.04}), **{
        k: {sub: v for sub, v in section.items() if f'{k}.{sub}' != key}
        for k, section in around.items()}}
    spec = parse_spec({'scenario': 'demo', 'set': fixed, 'grid': {key: values}, 'seeds': 1})
    runs = plan_runs(spec)
    assert len(runs) == 2
    first, last = (run.scenario().network for run in runs)
    assert second(last) and not second(first), key


def test_a_sweep_over_delay_and_loss_collects_the_statistics(tmp_path):
    """Two network keys, two values each: the loss shows in the delivered fraction, the
    delay in the ages, each as the model says."""
    spec = tmp_path / 'net.yaml'
    spec.write_text(json.dumps({
        'name': 'net', 'scenario': 'demo', 'set': SMALL,
        'grid': {'network.delay': [0.02, 0.1], 'network.loss': [0.0, 0.3]},
        'seeds': 2, 'metrics': ['eta', 'network_delivered', 'network_age_mean',
                                'network_age_max']}))
    assert sweep_main([str(spec), '--jobs', '1', '--out', str(tmp_path / 'out'), '--quiet',
                       '--no-plots']) == 0
    with open(tmp_path / 'out' / 'runs.csv', newline='') as stream:
        rows = list(csv.DictReader(stream))
    assert len(rows) == 8 and {r['status'] for r in rows} == {'completed'}
    for row in rows:
        delay, loss = float(row['network.delay']), float(row['network.loss'])
        delivered, age = float(row['network_delivered']), float(row['network_age_mean'])
        if loss == 0.0:
            assert delivered == 1.0
            # Nothing lost: every state used is exactly the fixed delay old.
            assert age == pytest.approx(delay, abs=1e-12)
            assert float(row['network_age_max']) == pytest.approx(delay, abs=1e-12)
        else:
            assert 0.55 < delivered < 0.85
            # A lost refresh leaves an older state in use (within max_age).
            assert delay < age < delay + 0.02 + 1e-12
            assert float(row['network_age_max']) == pytest.approx(delay + 0.02, abs=1e-12)


def test_sim_draws_the_network_figure(tmp_path):
    overrides = [f'{key}={json.dumps(value)}' for key, value in SMALL.items()]
    overrides.append('network={delay: 0.04, loss: 0.2}')
    argv = ['demo', '--out', str(tmp_path / 'net'), '--plots']
    assert sim_main(argv + [arg for o in overrides for arg in ('--set', o)]) == 0
    assert (tmp_path / 'net' / 'network.png').stat().st_size > 10_000
    with np.load(tmp_path / 'net' / 'timeseries.npz') as series:
        assert np.isfinite(series['network_delivered']).all()
    # Without the section, no network figure.
    argv = ['demo', '--out', str(tmp_path / 'plain'), '--plots', '--set', 'duration=0.1']
    assert sim_main(argv) == 0
    assert not (tmp_path / 'plain' / 'network.png').exists()
    assert (tmp_path / 'plain' / 'metrics.png').is_file()
