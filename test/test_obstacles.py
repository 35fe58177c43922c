"""Obstacles (``obstacles:``, :mod:`flock_swarm.core.obstacles`): the section's validation,
the beta-agents of Olfati-Saber 2006 against geometry, the beta term's oracles, and the runs."""

import numpy as np
import pytest
from numpy.testing import assert_allclose

from flock_swarm.cli.sim import main
from flock_swarm.core import potentials as pot
from flock_swarm.core.errors import ScenarioError
from flock_swarm.core.obstacles import (ObstacleSpec, beta_pairs, beta_term, clearances,
                                        parse_obstacles, phi_beta, sphere_beta_agents,
                                        wall_beta_agents)
from flock_swarm.core.run import simulate, simulate_stack
from flock_swarm.core.scenario import parse_scenario
from flock_swarm.presets import load, prepare

#: [OS06]'s parameters (Section VIII, as the notes give them): d = 7, r = 1.2 d, eps = 0.1,
#: h = 0.2, a = b = 5; d' = 0.6 d and r' = 1.2 d' are the section's defaults.
PAPER_LAW = {'name': 'olfati_saber_2006', 'r': 8.4, 'd': 7.0, 'eps': 0.1, 'h': 0.2, 'a': 5.0,
             'b': 5.0, 'c1': 0.5, 'c2': 0.5, 'navigation': 'bounded'}


class _Law:
    """The two attributes parse_obstacles reads of a law."""

    name = 'test_law'

    def __init__(self, accepts=True, d=7.0):
        self.accepts_obstacles, self.d = accepts, d


def mixed_spec(dim, **extra):
    """Return a map with two spheres and two walls in ``dim`` dimensions."""
    zeros = [0.0] * dim
    unit = [0.0] * (dim - 1) + [1.0]
    section = {'spheres': [{'centre': [5.0] + zeros[1:], 'radius': 2.0},
                           {'centre': [-6.0] + [3.0] * (dim - 1), 'radius': 1.5}],
               'walls': [{'point': [0.0] * (dim - 1) + [-8.0], 'normal': unit},
                         {'point': [20.0] + zeros[1:], 'normal': [-1.0] + zeros[1:]}],
               **extra}
    return parse_obstacles(section, dim, _Law())


# --------------------------------------------------------------------------------------------
# The section


def test_defaults_follow_the_paper():
    spec = parse_obstacles({'walls': [{'point': [0, 0], 'normal': [0, 1]}]}, 2, _Law(d=7.0))
    assert spec.active and spec.count == 1
    assert spec.d_beta == pytest.approx(0.6 * 7.0) and spec.r_beta == pytest.approx(1.2 * 4.2)
    assert (spec.h, spec.eps) == (0.9, 0.1)
    assert spec.c2_beta == pytest.approx(2.0 * np.sqrt(spec.c1_beta))
    assert not parse_obstacles(None, 2, _Law(accepts=False)).active


@pytest.mark.parametrize('section, key', [
    ({'spheres': [{'centre': [0, 0, 0], 'radius': 1}]}, 'obstacles.spheres[0].centre'),
    ({'spheres': [{'centre': [0, 0], 'radius': 0}]}, 'obstacles.spheres[0].radius'),
    ({'spheres': [{'centre': [0, 0], 'radius': -1}]}, 'obstacles.spheres[0].radius'),
    ({'spheres': [{'centre': [0, 0]}]}, 'obstacles.spheres[0].radius'),
    ({'spheres': [{'centre': [0, 0], 'radius': 1, 'colour': 'red'}]},
     'obstacles.spheres[0].colour'),
    ({'spheres': {'centre': [0, 0]}}, 'obstacles.spheres'),
    ({'walls': [{'point': [0, 0], 'normal': [0, 2]}]}, 'obstacles.walls[0].normal'),
    ({'walls': [{'point': [0, 0], 'normal': [0, 0]}]}, 'obstacles.walls[0].normal'),
    ({'walls': [{'point': [0], 'normal': [0, 1]}]}, 'obstacles.walls[0].point'),
    ({'walls': [{'normal': [0, 1]}]}, 'obstacles.walls[0].point'),
    ({'d_beta': -1}, 'obstacles.d_beta'),
    ({'r_beta': 0}, 'obstacles.r_beta'),
    ({'c1_beta': 'high'}, 'obstacles.c1_beta'),
    ({'c2_beta': -2}, 'obstacles.c2_beta'),
    ({'h': 1.0}, 'obstacles.h'),
    ({'eps': 0}, 'obstacles.eps'),
    ({'cylinders': []}, 'obstacles.cylinders'),
    ([1, 2], 'obstacles'),
])
def test_invalid_values_name_their_key(section, key):
    with pytest.raises(ScenarioError) as err:
        parse_obstacles(section, 2, _Law())
    assert err.value.key == key
    assert '\n' not in str(err.value)


def test_a_law_without_obstacles_or_without_d_is_refused_in_one_line():
    walls = {'walls': [{'point': [0, 0], 'normal': [0, 1]}]}
    with pytest.raises(ScenarioError, match='does not accept obstacles') as err:
        parse_obstacles(walls, 2, _Law(accepts=False))
    assert err.value.key == 'obstacles'
    with pytest.raises(ScenarioError, match='no desired distance') as err:
        parse_obstacles(walls, 2, _Law(d=None))
    assert err.value.key == 'obstacles.d_beta'
    assert parse_obstacles({**walls, 'd_beta': 2.0}, 2, _Law(d=None)).r_beta == 2.4


def test_sim_refuses_an_agent_starting_inside_and_a_law_that_does_not_accept(capsys,
                                                                             tmp_path):
    # Fig. 2's seed puts agent 61 at (28.18, 1.29).
    inside = 'obstacles={spheres: [{centre: [30, 0], radius: 3}]}'
    out = ['--quiet', '--out', str(tmp_path)]
    assert main(['su2009_fig2', '--set', inside, *out]) == 2
    line = capsys.readouterr().err.strip()
    assert line.startswith('sim: error: obstacles.spheres[0]: agent ') and '\n' not in line
    assert 'starts inside it' in line
    assert main(['zhou2012_sec51', '--set', inside, *out]) == 2
    line = capsys.readouterr().err.strip()
    assert line == ('sim: error: obstacles: protocol zhou_pseudo_leader does not accept '
                    'obstacles (docs/obstacles.md lists the laws that do)')


# --------------------------------------------------------------------------------------------
# The beta-agents against geometry


@pytest.mark.parametrize('dim', [2, 3])
def test_distance_to_the_beta_agent_is_the_distance_to_the_surface(dim):
    rng = np.random.default_rng(27)
    q = rng.uniform(-15.0, 15.0, (400, dim))
    p = rng.normal(size=(400, dim))
    centre, radius = rng.uniform(-3, 3, (400, dim)), rng.uniform(0.5, 4.0, 400)
    qh, ph = sphere_beta_agents(q, p, centre, radius)
    # On the sphere, and as far from the agent as the surface is.
    assert_allclose(np.linalg.norm(qh - centre, axis=1), radius, rtol=1e-12)
    assert_allclose(np.linalg.norm(qh - q, axis=1),
                    np.abs(np.linalg.norm(q - centre, axis=1) - radius), atol=1e-12)
    # The closest point: no point of a dense sample of the sphere is closer.
    sample = rng.normal(size=(2000, dim))
    sample /= np.linalg.norm(sample, axis=1, keepdims=True)
    for i in range(5):
        surface = centre[i] + radius[i] * sample
        assert np.linalg.norm(qh[i] - q[i]) <= np.linalg.norm(surface - q[i], axis=1).min()
    # ph = mu P p: tangential (orthogonal to the radius) with length mu |P p|.
    a = (q - centre) / np.linalg.norm(q - centre, axis=1, keepdims=True)
    assert_allclose(np.einsum('ek,ek->e', ph, a), 0.0, atol=1e-12)
    mu = radius / np.linalg.norm(q - centre, axis=1)
    tangential = p - a * np.einsum('ek,ek->e', p, a)[:, None]
    assert_allclose(ph, mu[:, None] * tangential, rtol=1e-12, atol=1e-12)

    normal = rng.normal(size=(400, dim))
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    point = rng.uniform(-3, 3, (400, dim))
    qh, ph = wall_beta_agents(q, p, point, normal)
    signed = np.einsum('ek,ek->e', q - point, normal)
    assert_allclose(np.einsum('ek,ek->e', qh - point, normal), 0.0, atol=1e-11)
    assert_allclose(np.linalg.norm(qh - q, axis=1), np.abs(signed), rtol=1e-12, atol=1e-12)
    assert_allclose(np.einsum('ek,ek->e', ph, normal), 0.0, atol=1e-12)
    assert_allclose(ph + normal * np.einsum('ek,ek->e', p, normal)[:, None], p, atol=1e-12)


def test_clearances_are_the_signed_distances():
    spec = mixed_spec(2)
    q = np.array([[5.0, 3.0], [-6.0, 3.0], [0.0, -8.5], [19.0, 0.0]])
    expected = np.array([[1.0, np.hypot(11, 0) - 1.5, 11.0, 15.0],
                         [np.hypot(11, 3) - 2.0, -1.5, 11.0, 26.0],
                         [np.hypot(5, 8.5) - 2.0, np.hypot(6, 11.5) - 1.5, -0.5, 20.0],
                         [np.hypot(14, 0) - 2.0, np.hypot(25, 3) - 1.5, 8.0, 1.0]])
    assert_allclose(clearances(spec, q), expected, rtol=1e-12)


# --------------------------------------------------------------------------------------------
# The beta term


def test_phi_beta_repels_below_d_beta_and_vanishes_beyond():
    d_b = pot.sigma_of_distance(4.2, 0.1)
    z = np.linspace(0.0, 3 * d_b, 301)
    action = phi_beta(z, d_b, 0.9)
    assert (action[z < d_b] < 0).all() and (action[z >= d_b] == 0).all()
    # On the bump's plateau, exactly sigma_1(z - d_beta) - 1.
    low = z < 0.9 * d_b
    assert_allclose(action[low], pot.sigma_1(z[low] - d_b) - 1.0, rtol=1e-15)


@pytest.mark.parametrize('dim', [2, 3])
def test_the_term_is_zero_beyond_the_sensing_range_and_not_within(dim):
    spec = mixed_spec(dim)
    rng = np.random.default_rng(5)
    q = rng.uniform(-30, 30, (3000, dim))
    p = rng.normal(size=(3000, dim))
    c = clearances(spec, q)
    u = beta_term(spec, q, p)
    far = (np.abs(c) >= spec.r_beta).all(axis=1)
    assert far.sum() > 100 and (~far).sum() > 100
    assert (u[far] == 0.0).all()
    # Within d' the repulsion acts (b_ik > 0 below d' and phi_beta < 0).
    close = ((c > 0) & (c < 0.5 * spec.d_beta)).any(axis=1)
    assert close.sum() > 10 and (np.abs(u[close]).max(axis=1) > 0).all()
    # The pairs are exactly those within r'.
    agent, obstacle = beta_pairs(spec, q)
    assert set(zip(agent.tolist(), obstacle.tolist())) == set(
        zip(*np.nonzero(np.abs(c) < spec.r_beta)))


def test_the_term_pushes_out_along_the_normal_and_damps_the_normal_velocity():
    spec = parse_obstacles({'walls': [{'point': [0, 0], 'normal': [0, 1]}]}, 2, _Law())
    q = np.array([[0.0, 1.0], [3.0, 2.0]])
    u = beta_term(spec, q, np.zeros((2, 2)))
    assert (u[:, 0] == 0).all() and (u[:, 1] > 0).all()
    # Moving along the wall: no damping (ph = P p = p); towards it: damped.
    along = beta_term(spec, q, np.array([[1.0, 0.0], [1.0, 0.0]]))
    assert_allclose(along, u, rtol=0, atol=0)
    towards = beta_term(spec, q, np.array([[0.0, -1.0], [0.0, -1.0]]))
    assert (towards[:, 1] > u[:, 1]).all()


@pytest.mark.parametrize('dim', [2, 3])
def test_the_sum_over_a_symmetric_configuration(dim):
    """Agents mirrored through a sphere's centre (positions and velocities) get opposite
    terms: their sum is zero; agents mirrored through a wall's normal line get terms with
    opposite tangential parts: the sum is along the normal."""
    rng = np.random.default_rng(11)
    spec = parse_obstacles({'spheres': [{'centre': [0.0] * dim, 'radius': 2.0}]}, dim,
                           _Law(d=3.0))
    half = rng.normal(size=(50, dim))
    half *= (2.0 + rng.uniform(0.05, 2.0, (50, 1))) / np.linalg.norm(half, axis=1)[:, None]
    p = rng.normal(size=(50, dim))
    u = beta_term(spec, np.concatenate([half, -half]), np.concatenate([p, -p]))
    assert np.abs(u).max() > 0.1
    assert_allclose(u.sum(axis=0), 0.0, atol=1e-12)

    spec = parse_obstacles({'walls': [{'point': [0.0] * dim, 'normal': [0.0] * (dim - 1)
                                       + [1.0]}]}, dim, _Law(d=3.0))
    q = np.abs(half)
    mirror = np.concatenate([np.full((50, dim - 1), -1.0), np.ones((50, 1))], axis=1)
    u = beta_term(spec, np.concatenate([q, q * mirror[0]]), np.concatenate([p, p * mirror[0]]))
    assert np.abs(u[:, -1]).max() > 0.1
    assert_allclose(u[:, :-1].sum(axis=0), 0.0, atol=1e-12)


def test_a_row_is_the_same_alone_in_a_group_and_in_the_swarm():
    spec = mixed_spec(3)
    rng = np.random.default_rng(3)
    q, p = rng.uniform(-12, 12, (500, 3)), rng.normal(size=(500, 3))
    whole = beta_term(spec, q, p)
    ids = np.array([3, 77, 250, 499])
    assert np.array_equal(beta_term(spec, q[ids], p[ids]), whole[ids])
    for i in ids:
        assert np.array_equal(beta_term(spec, q[i:i + 1], p[i:i + 1])[0], whole[i])


# --------------------------------------------------------------------------------------------
# Runs


def head_on(speed, dim=2, duration=15.0, **extra):
    """Return two agents (farther apart than r) flying at ``speed`` head-on at a wall 15 m
    ahead, behind a leader that flies through it: the pull of the navigation term keeps them
    pressed against the wall."""
    rest = [0.0] * (dim - 2)
    return {'name': 'head_on', 'dim': dim, 'n_agents': 2, 'dt': 0.01, 'duration': duration,
            'record_every': 10,
            'protocol': PAPER_LAW,
            'initial': {'positions': [[0.0, -20.0, *rest], [0.0, 20.0, *rest]],
                        'velocities': [[speed, 0.0, *rest], [speed, 0.0, *rest]]},
            'leader': {'model': 'constant_velocity', 'position': [0.0, 0.0, *rest],
                       'velocity': [speed, 0.0, *rest]},
            'obstacles': {'walls': [{'point': [15.0, 0.0, *rest],
                                     'normal': [-1.0, 0.0, *rest]}], **extra}}


@pytest.mark.parametrize('speed', [1.0, 2.0, 5.0, 10.0, 20.0])
def test_an_agent_driven_head_on_at_a_wall_never_penetrates_it(speed):
    sc, _ = prepare(head_on(speed))
    res = simulate(sc)
    s = res.summary
    assert s['status'] == 'completed'
    assert s['obstacle_penetrations'] == 0 and s['obstacle_collisions'] == 0
    assert 0.0 < s['obstacle_clearance_min'] < sc.obstacles.d_beta
    # It stopped at the wall and stays there (the leader flies on).
    assert res.series['q'][-1, :, 0].max() < 15.0
    assert s['obstacle_clearance_min'] == pytest.approx(res.series['obstacle_clearance'].min(),
                                                        abs=0.05)


def test_without_the_section_nothing_changes_and_an_empty_one_changes_nothing():
    sc = load('su2009_fig6', ['duration=2'])
    empty = load('su2009_fig6', ['duration=2', 'obstacles={}'])
    assert not sc.obstacles.active and not empty.obstacles.active
    a, b = simulate(sc), simulate(empty)
    assert not any(k.startswith('obstacle') for k in a.summary)
    assert 'obstacle_clearance' not in a.series
    for name, values in a.series.items():
        assert np.array_equal(values, b.series[name]), name
    assert {k: v for k, v in a.summary.items() if k != 'wall_time_s'} == \
        {k: v for k, v in b.summary.items() if k != 'wall_time_s'}


def test_stacked_runs_with_obstacles_equal_their_own_runs():
    base = head_on(5.0, duration=4.0)
    scenarios = [parse_scenario({**base, 'seed': s, 'initial': {
        'position_box': [[-5, 0], [-20, 20]], 'velocity_box': [[4, 6], [0, 0]]},
        'n_agents': 6}) for s in (1, 2)]
    stacked = simulate_stack(scenarios)
    for sc, res in zip(scenarios, stacked):
        alone = simulate(sc)
        for name, values in alone.series.items():
            assert np.array_equal(res.series[name], values), name
        assert res.summary['obstacle_clearance_min'] == alone.summary['obstacle_clearance_min']
    other = parse_scenario({**base, 'obstacles': {'walls': [{'point': [16.0, 0.0],
                                                             'normal': [-1.0, 0.0]}]}})
    with pytest.raises(ValueError, match='obstacles'):
        simulate_stack([scenarios[0], other])


def test_spec_is_hashable_and_compares_by_value():
    a, b = mixed_spec(2), mixed_spec(2)
    assert a == b and hash(a) == hash(b) and a != ObstacleSpec()


def obstacle_pixels(path):
    """Return how many pixels of a figure have the obstacles' hue (brown: red > green > blue
    by some margin; the agents' red and blue, the grey panes and the white do not)."""
    from PIL import Image
    with Image.open(path) as image:
        rgb = np.asarray(image.convert('RGB'), dtype=int)
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    return int(((r - g > 6) & (g - b > 6) & (r - b < 60)).sum())


@pytest.mark.parametrize('dim', [2, 3])
def test_every_figure_of_positions_draws_the_obstacles(tmp_path, dim):
    from flock_swarm.plots import (animate_flock, plot_snapshots, plot_timeseries,
                                   plot_trajectories)
    sc, _ = prepare(head_on(5.0, dim, duration=4.0, spheres=[
        {'centre': [8.0, 0.0] + [0.0] * (dim - 2), 'radius': 2.0}]))
    series = simulate(sc).series
    spec = sc.obstacles
    paths = [plot_trajectories(series, tmp_path, obstacles=spec),
             plot_snapshots(series, tmp_path, radius=sc.law.radius, times=[4.0],
                            obstacles=spec),
             *plot_timeseries(series, tmp_path, sc.name, spec)[:1]]
    assert [p.name for p in paths] == ['trajectories.png', 'snapshots.png', 'trajectories.png']
    for path in paths:
        assert obstacle_pixels(path) > 100, path.name
    frames = animate_flock(series, tmp_path, radius=sc.law.radius, max_frames=2, mp4=False,
                           obstacles=spec)
    assert frames[0].stat().st_size > 1000
    # Without the map, nothing of its colour.
    assert obstacle_pixels(plot_trajectories(series, tmp_path, filename='bare.png')) == 0


def test_the_docs_figure_script_runs(tmp_path):
    """scripts/figures/obstacles.py, which draws docs/figures/obstacles.png, still runs and
    draws the obstacles."""
    import runpy
    from pathlib import Path
    script = Path(__file__).resolve().parents[1] / 'scripts' / 'figures' / 'obstacles.py'
    main_of = runpy.run_path(str(script))['main']
    assert main_of(['--out', str(tmp_path)]) == 0
    assert obstacle_pixels(tmp_path / 'obstacles.png') > 1000


def test_a_dt_beyond_the_beta_terms_bound_is_refused_in_one_line(capsys, tmp_path):
    # c2_beta = 50: dt < 2 / 50 = 0.04 s; the scenario's 0.05 s is refused, 0.02 s is not.
    gains = 'obstacles.c2_beta=50'
    assert main(['su2009_fig2', '--set', 'obstacles={walls: [{point: [0, -5], normal: [0, 1]}]}',
                 '--set', gains, '--set', 'dt=0.05', '--quiet', '--out', str(tmp_path)]) == 2
    line = capsys.readouterr().err.strip()
    assert line.startswith('sim: error: dt: 0.05 exceeds the stability bound 0.04 of the '
                           'beta term of the obstacles (c1_beta = 10, c2_beta = 50)')
    sc, _ = prepare('su2009_fig2', ['obstacles={walls: [{point: [0, -5], normal: [0, 1]}]}',
                                    gains, 'duration=0.04'])
    assert sc.obstacles.c2_beta == 50


def test_a_sweep_varies_the_section_and_collects_the_obstacle_metrics(tmp_path):
    """A sweep over ``obstacles.c2_beta`` (stacked seeds) collects the three metrics, each
    run's equal to its own ``sim`` run."""
    import csv
    import json

    from flock_swarm.cli.sweep import main as sweep_main
    base = head_on(5.0, duration=4.0)
    base['initial'] = {'position_box': [[-5, 0], [-20, 20]], 'velocity_box': [[4, 6], [0, 0]]}
    base['n_agents'] = 6
    (tmp_path / 'scene.yaml').write_text(json.dumps(base))
    spec = {'name': 'walls', 'scenario': str(tmp_path / 'scene.yaml'),
            'grid': {'obstacles.c2_beta': [3.0, 8.0]}, 'seeds': 2,
            'metrics': ['obstacle_clearance_min', 'obstacle_penetrations',
                        'obstacle_collisions'], 'stack_agents': 12}
    (tmp_path / 'walls.yaml').write_text(json.dumps(spec))
    assert sweep_main([str(tmp_path / 'walls.yaml'), '--jobs', '1', '--out',
                       str(tmp_path / 'out'), '--quiet', '--no-plots']) == 0
    with open(tmp_path / 'out' / 'runs.csv', newline='') as stream:
        rows = list(csv.DictReader(stream))
    assert len(rows) == 4
    for row in rows:
        sc = parse_scenario({**base, 'seed': int(row['seed']),
                             'obstacles': {**base['obstacles'],
                                           'c2_beta': float(row['obstacles.c2_beta'])}})
        alone = simulate(sc).summary
        assert float(row['obstacle_clearance_min']) == pytest.approx(
            alone['obstacle_clearance_min'], rel=0, abs=1e-9)
        assert int(row['obstacle_penetrations']) == alone['obstacle_penetrations']
        assert int(row['obstacle_collisions']) == alone['obstacle_collisions']


@pytest.mark.parametrize('kind', ['spheres', 'walls'])
def test_a_map_of_one_kind_has_empty_arrays_of_the_other(kind):
    """A map of spheres only (the squeeze preset's) or walls only gives ``(0, dim)`` arrays for
    the other kind: drawing and the term once failed on an empty reshape."""
    full = mixed_spec(2)
    spec = ObstacleSpec(**{kind: getattr(full, kind), 'd_beta': full.d_beta,
                           'r_beta': full.r_beta})
    assert spec.centres.shape == (len(spec.spheres), 2)
    assert spec.points.shape == spec.normals.shape == (len(spec.walls), 2)
    q = np.array([[3.0, 0.0], [0.0, -7.0]])
    assert beta_term(spec, q, np.zeros_like(q)).shape == (2, 2)


def test_sim_plots_a_preset_with_spheres_only(tmp_path):
    """`sim olfati_saber2006_squeeze --plots` (two spheres, no wall) draws its figures."""
    assert main(['olfati_saber2006_squeeze', '--set', 'duration=1', '--out', str(tmp_path),
                 '--plots']) == 0
    assert (tmp_path / 'trajectories.png').stat().st_size > 1000
