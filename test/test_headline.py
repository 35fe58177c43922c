"""The headline of a run (``metrics.headline``, ``metrics.claim``): how it reads, what it orders.

The scenario key is validated in test_scenario_validation.py; ``sim``'s last line in
test_sim.py; ``swarm``'s, the demo's and ``/swarm/metrics``' in test_nodes.py.
"""

import pytest

from flock_swarm.core.headline import (DEFAULT_KEYS, READINGS, Headline, headline_metrics,
                                       lead_with, progress_text, reading, result_line,
                                       run_mapping)
from flock_swarm.core.metrics import STEP_METRICS
from flock_swarm.core.summary import compared_metrics

#: A summary as ``sim`` writes it (the keys a result line reads).
SUMMARY = {'status': 'completed', 't_final': 10.0, 'eta': 0.0, 'velocity_mismatch_max': 0.7754,
           'com_position_error': 0.31548, 'com_velocity_error': 0.73912,
           'min_pair_distance': 1.25, 'collisions': 0, 'components_final': 1,
           'wall_time_s': 1.43}


def old_sim_line(s: dict) -> str:
    """Return the line ``sim`` printed before scenarios could choose a headline."""
    return (f'{s["status"]} at t = {s["t_final"]:g} s: eta = {s["eta"]:.3f}, '
            f'velocity mismatch = {s["velocity_mismatch_max"]:.3g}, '
            f'collisions = {s["collisions"]}, components = {s["components_final"]} '
            f'({s["wall_time_s"]:.1f} s wall)')


def old_swarm_line(s: dict) -> str:
    """Return the line ``swarm`` printed before scenarios could choose a headline."""
    return (f'{s["status"]} at t = {s["t_final"]:g} s: eta = '
            f'{s["eta"]:.3f}, velocity mismatch = {s["velocity_mismatch_max"]:.3g}, '
            f'collisions = {s["collisions"]}, missed commands = '
            f'{s.get("missed_commands", 0)} ({s.get("wall_time_s", 0):.1f} s wall)')


@pytest.mark.parametrize('summary', [
    SUMMARY,
    dict(SUMMARY, status='interrupted', t_final=3.25, eta=0.96667, velocity_mismatch_max=12345.6,
         collisions=13, components_final=4, wall_time_s=0.04),
    dict(SUMMARY, missed_commands=17),
])
def test_without_a_headline_the_lines_are_as_they_were(summary):
    assert result_line(summary, Headline(), ('collisions', 'components_final')) \
        == old_sim_line(summary)
    assert result_line(summary, Headline(), ('collisions', 'missed_commands')) \
        == old_swarm_line(summary)


def test_the_line_leads_with_the_headline_and_the_claim():
    headline = Headline(('com_position_error', 'com_velocity_error'),
                        'Su 2009 Fig. 6: -> 0 exponentially')
    assert result_line(SUMMARY, headline, ('collisions', 'components_final')) == (
        'completed at t = 10 s: COM position error = 0.315 m, COM velocity error = 0.739 m/s '
        '(Su 2009 Fig. 6: -> 0 exponentially); collisions = 0, components = 1 (1.4 s wall)')
    # eta stays in the summary, not on the line of a run about something else.
    assert 'eta' not in result_line(SUMMARY, headline, ('collisions',))


def test_a_count_in_the_headline_is_not_repeated_after_it():
    headline = Headline(('components_final', 'collisions'), 'Olfati-Saber 2003 Sec. 5: one flock')
    assert result_line(SUMMARY, headline, ('collisions', 'components_final')) == (
        'completed at t = 10 s: components = 1, collisions = 0 '
        '(Olfati-Saber 2003 Sec. 5: one flock); 1.4 s wall')
    assert result_line(SUMMARY, Headline(('collisions',)), ('collisions',)) \
        == 'completed at t = 10 s: collisions = 0 (1.4 s wall)'


def test_progress_lines_read_as_they_did_without_a_headline():
    latest = {'eta': 0.5, 'velocity_mismatch_max': 0.30001, 'com_position_error': 2.0}
    assert progress_text(latest, Headline()) == 'eta = 0.50  mismatch = 0.3'
    # Before the first measured step: zeros, as before.
    assert progress_text({}, Headline()) == 'eta = 0.00  mismatch = 0'
    assert progress_text(latest, Headline(('com_position_error', 'collisions'))) \
        == 'COM error = 2'
    # Nothing of the headline is measured at every step: the default's values.
    assert progress_text(latest, Headline(('collisions',))) == 'eta = 0.50  mismatch = 0.3'


def test_the_live_values_lead_with_the_headline():
    values = {key: float(k) for k, key in enumerate(STEP_METRICS)}
    values.update(step=7, missed_commands=0)
    assert list(lead_with(values, Headline())) == list(values)
    led = lead_with(values, Headline(('components_final', 'collisions', 'com_position_error')))
    assert list(led)[:2] == ['components', 'com_position_error']
    assert led == values and sorted(led) == sorted(values)


def test_every_measure_may_lead_and_reads_with_a_unit_or_by_its_key():
    assert headline_metrics() == compared_metrics()
    assert set(DEFAULT_KEYS) <= set(headline_metrics())
    for key in headline_metrics():
        r = reading(key)
        assert r.label and r.short
        # A measure recorded at every step is published live under the key the world uses
        # (the obstacle clearance by a run with obstacles).
        assert r.live is None or r.live in (*STEP_METRICS, 'obstacle_clearance'), key
    assert reading('a_plugin_measure').label == 'a_plugin_measure'
    assert set(READINGS) - set(headline_metrics()) == {'missed_commands'}


@pytest.mark.parametrize('raw, want', [
    ({'name': 'x', 'metrics': {'eta_tolerance': 0.5, 'headline': ['eta'], 'claim': 'c'}},
     {'name': 'x', 'metrics': {'eta_tolerance': 0.5}}),
    ({'name': 'x', 'metrics': {'headline': ['eta']}}, {'name': 'x'}),
    ({'name': 'x', 'metrics': {}}, {'name': 'x', 'metrics': {}}),
    ({'name': 'x', 'metrics': None}, {'name': 'x', 'metrics': None}),
    ({'name': 'x'}, {'name': 'x'}),
])
def test_a_run_does_not_depend_on_its_headline(raw, want):
    assert run_mapping(raw) == want
