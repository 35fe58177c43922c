"""Launch-free tests of a swarm: the public testing API and its pytest plugin.

What the project's own tests use, for a user's test scripts: a ROS domain id of its own per
test, the whole swarm (world, leader, agents) in the test's process on one executor with its
own ``rclpy`` context, bounded waits, the recorded bag and summary read back, and a check that
a lockstep ROS run equals the reference simulator ``sim``::

    from flock_swarm.testing import Swarm, assert_matches_sim

    def test_my_law_flies(tmp_path, ros_domain):
        with Swarm('my_scenario.yaml', tmp_path / 'run', domain_id=ros_domain) as swarm:
            swarm.spin_until(lambda: swarm.world.k >= 10, timeout=60, what='step 10')
        run = swarm.result()
        assert run.summary['status'] == 'completed'

    def test_my_law_equals_sim(tmp_path, ros_domain):
        assert_matches_sim('my_scenario.yaml', tmp_path / 'run', domain_id=ros_domain, atol=0)

Installed with flock_swarm, the module is also a pytest plugin (entry point ``pytest11``,
name ``flock_swarm``) with the fixtures :func:`ros_domain`, :func:`other_ros_domain`,
:func:`flock_swarm_run` and :func:`in_process_swarm`. It imports no ``rclpy`` (nor NumPy)
until a test uses it: every pytest run in the virtualenv loads the plugin.
"""

from __future__ import annotations

import itertools
import json
import os
import time
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator

import pytest

from flock_swarm.core.summary import sim_only_keys
# The swarm runner imports no rclpy, NumPy or YAML until a run starts (this plugin is loaded by
# every pytest run of the environment).
from flock_swarm.nodes.swarm_runner import (DOMAIN_SPAN, DOMAINS_VARIABLE,  # noqa: F401
                                            InProcessSwarm, RUN_TIMEOUT, SwarmRun, domain_ranges,
                                            release_domain, unique_domain)

#: The environment variable that limits DDS discovery, and the value the fixtures default to:
#: a test never talks to, or hears from, another host.
DISCOVERY_RANGE = 'ROS_AUTOMATIC_DISCOVERY_RANGE'
LOCALHOST = 'LOCALHOST'
#: The poll interval [s] of :func:`wait_for`.
POLL = 0.05
#: Keys of ``sim``'s summary that are not the swarm's but the simulator's own: its wall time,
#: and its count of pseudo-leader reselections (the world does not keep one); from the table
#: of summary keys (:mod:`flock_swarm.core.summary`, which imports no NumPy).
SIM_ONLY = sim_only_keys()


def wait_for(condition: Callable[[], Any], timeout: float, what: str = 'the condition',
             poll: float = POLL) -> None:
    """Poll ``condition`` until it holds (for files, processes: things that need no spinning).

    :param condition: called every ``poll`` seconds until it returns a true value.
    :param timeout: wall-clock bound [s].
    :param what: what is awaited, for the failure message.
    :param poll: the poll interval [s].
    :raises AssertionError: ``timed out after T s waiting for WHAT``.
    """
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError(f'timed out after {timeout:g} s waiting for {what}')
        time.sleep(poll)


def spin_until(executor, condition: Callable[[], Any], timeout: float,
               what: str = 'the condition') -> None:
    """Spin ``executor`` until ``condition`` holds (for a test's own nodes).

    :param executor: an rclpy executor holding the nodes that make the condition come true.
    :param condition: checked after every callback (or every 0.1 s without one).
    :param timeout: wall-clock bound [s].
    :param what: what is awaited, for the failure message.
    :raises AssertionError: ``timed out after T s waiting for WHAT``.
    """
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError(f'timed out after {timeout:g} s waiting for {what}')
        executor.spin_once(timeout_sec=0.1)


#: World, leader and agents spinning in this process: a context manager for tests. The
#: swarm runner's :class:`~flock_swarm.nodes.swarm_runner.InProcessSwarm` itself (``swarm`` without
#: ``--processes`` runs the same class): ``Swarm(scenario, out, overrides=(), seed=None,
#: domain_id=None, **args)`` resolves the scenario as ``swarm`` resolves it into
#: ``out/scenario.yaml`` (the domain id defaults to :func:`unique_domain`); ``world``,
#: ``leader``, ``agents``, ``executor``, ``context``, ``add``, ``add_leader``, ``add_agents``,
#: ``remove``; :meth:`~InProcessSwarm.spin_until` (bounded, fails with a message),
#: :meth:`~InProcessSwarm.spin_to_end`, :meth:`~InProcessSwarm.run` and
#: :meth:`~InProcessSwarm.result` (a :class:`SwarmRun`).
Swarm = InProcessSwarm


def run_swarm(scenario: str | Path, out: Path, overrides: Iterable[str] = (),
              seed: int | None = None, domain_id: int | None = None,
              timeout: float = RUN_TIMEOUT, **swarm_args) -> SwarmRun:
    """Run a scenario through the nodes, in this process, to its end.

    :param timeout: wall-clock bound [s] of the whole run.
    :return: the outputs.

    The other parameters are :class:`Swarm`'s.
    """
    with Swarm(scenario, out, overrides, seed, domain_id, **swarm_args) as swarm:
        return swarm.run(timeout)


def compare_runs(want: dict, want_series: dict, got: dict, got_series: dict,
                 atol: float) -> list[str]:
    """Return the differences between two runs beyond ``atol`` (empty: they match).

    Every key of ``want`` (the summary and the time series) must be in ``got``; numbers and
    float arrays may differ by ``atol`` (0: bit for bit), everything else must be equal. The
    problems of :func:`flock_swarm.analysis.compare.compare_runs` (the reference first, as
    here).

    :param want: the reference summary.
    :param want_series: the reference time series.
    :param got: the summary compared with it.
    :param got_series: the time series compared with it.
    :param atol: the absolute tolerance.
    :return: one line per difference.
    """
    from flock_swarm.analysis import compare

    return compare.compare_runs(want, want_series, got, got_series, atol).problems


def assert_matches_sim(scenario: str | Path, out: Path, overrides: Iterable[str] = (),
                       seed: int | None = None, atol: float = 0.0,
                       domain_id: int | None = None, timeout: float = RUN_TIMEOUT,
                       processes: bool = False, container: bool = False,
                       **swarm_args) -> SwarmRun:
    """Run a scenario through the nodes (lockstep) and assert it equals ``sim``'s run.

    The summary (every key ``sim`` writes but :data:`SIM_ONLY`, the law's adaptive state
    included) and every recorded time series must agree to ``atol``; ``atol=0`` demands bit
    for bit. The ROS run must be complete: every agent answered every step and the leader
    was never missed (otherwise it is not the run ``sim`` computes, and the comparison would
    say nothing).

    :param atol: the absolute tolerance.
    :param processes: run every node as its own process, as ``swarm --processes`` does
        (:func:`~flock_swarm.nodes.swarm_runner.run_processes`; ``swarm_args`` are then its
        keyword arguments), instead of in this process.
    :param container: with ``processes``, host every agent in one process (``swarm
        --processes --container``) instead of one process per agent.
    :return: the ROS run's outputs.
    :raises AssertionError: listing every difference.

    The other parameters are :func:`run_swarm`'s.
    """
    from flock_swarm.core.run import simulate
    from flock_swarm.outputs import json_text

    if processes:
        from flock_swarm.nodes.swarm_runner import resolve_scenario, run_processes

        path = resolve_scenario(str(scenario), list(overrides), seed, Path(out))
        run_processes(path, Path(out), mode='lockstep',
                      domain_id=unique_domain() if domain_id is None else domain_id,
                      timeout=timeout, container=container, **swarm_args)
        run = SwarmRun(out)
    else:
        run = run_swarm(scenario, out, overrides, seed, domain_id, timeout, mode='lockstep',
                        **swarm_args)
    summary = run.summary
    incomplete = {key: summary.get(key) for key in ('missed_commands', 'leader_missed')
                  if summary.get(key)}
    if summary.get('status') != 'completed' or incomplete:
        raise AssertionError(f'the ROS run is not comparable with sim: status '
                             f'{summary.get("status")!r}, {incomplete or "nothing missed"}')
    ref = simulate(run.scenario)
    # Through JSON, as the run's summary.json was written, so both sides are plain values.
    want = {k: v for k, v in json.loads(json_text(ref.summary)).items() if k not in SIM_ONLY}
    problems = compare_runs(want, ref.series, summary, run.timeseries(), atol)
    if problems:
        raise AssertionError(f'the ROS run of {run.scenario.name} differs from sim in '
                             f'{len(problems)} place(s):\n  ' + '\n  '.join(problems))
    return run


#: What :func:`check_law` runs a bare law in: a small 2-D swarm behind a leader at constant
#: velocity, half of it informed, in a box of the law's radius (so it has neighbours).
CHECK_STEPS = 20
#: The relative tolerance between one agent's ``local_control`` and the swarm's row: it sums
#: its neighbours' terms in another order than the simulator's ``bincount``.
LOCAL_RTOL = 1e-9


def check_law(law_or_scenario: Any, overrides: Iterable[str] = (), steps: int = CHECK_STEPS,
              seed: int | None = None) -> dict:
    """Check a law the way a plugin's own tests should, without ROS; raise on the first fault.

    On the scenario's realisation, for ``steps`` steps of the simulator:

    - its ``antisymmetric`` claim (on random states, when the scenario is loaded);
    - the shapes and finiteness of ``pair``, ``combine`` and ``state_rate`` at every step;
    - every agent alone (:func:`~flock_swarm.core.laws.evaluation.local_control`, a robot that
      knows its neighbours' states) equals its row of the simulator's ``u``
      (:func:`~flock_swarm.core.laws.evaluation.swarm_control`) to :data:`LOCAL_RTOL`, and each
      half of the swarm as a container hosts it
      (:func:`~flock_swarm.core.laws.evaluation.group_control`) equals its rows bit for bit.

    :param law_or_scenario: a law instance (run in a small 2-D swarm around it, see
        :data:`CHECK_STEPS`), or a scenario (preset name, file or mapping) that uses it.
    :param overrides: ``key=value`` overrides of the scenario (``sim --set``).
    :param steps: how many steps to check (the scenario's own count if it is shorter).
    :param seed: replaces the scenario's seed.
    :return: ``{'steps': checked, 'agents': n, 'largest_local_deviation': relative}``.
    :raises AssertionError: naming the law, the step and what differs (a
        :class:`~flock_swarm.core.errors.ScenarioError` of the scenario or the law is
        turned into one too).
    """
    import numpy as np

    from flock_swarm.core.dynamics import step_agents
    from flock_swarm.core.errors import ScenarioError
    from flock_swarm.core.laws.base import Law
    from flock_swarm.core.laws.evaluation import advance_state, output_problem, pair_sums
    from flock_swarm.core.leaders.base import VirtualLeader
    from flock_swarm.core.run import interaction_graph, static_graph
    from flock_swarm.presets import prepare

    scenario = _law_scenario(law_or_scenario) if isinstance(law_or_scenario, Law) \
        else law_or_scenario
    try:
        sc, real = prepare(scenario, overrides, seed)
    except ScenarioError as exc:
        raise AssertionError(f'the scenario or the law is refused: {exc}') from None
    law, n, dt = sc.law, sc.n_agents, sc.dt
    leader = VirtualLeader(sc.leader.model, sc.leader.position, sc.leader.velocity)
    intrinsic = sc.intrinsic.velocity_field() if sc.intrinsic is not None else None
    static = static_graph(sc, real)
    q, p, agents = real.q0.copy(), real.p0.copy(), real.agents
    halves = (np.arange(n // 2), np.arange(n // 2, n))
    worst = 0.0
    count = min(steps, sc.steps)
    # A diverging law is reported by the checks below, not by NumPy's warnings.
    with np.errstate(all='ignore'):
        for k in range(count):
            t, state = k * dt, leader.state
            edges = interaction_graph(sc, real, q, static)
            try:
                u, deviation = _check_step(law, q, p, edges, state, agents, dt, t, halves)
            except ScenarioError as exc:
                raise AssertionError(f'step {k}: {exc.reason}') from None
            except AssertionError as exc:
                raise AssertionError(f'step {k} (t = {t:g} s): {exc}') from None
            worst = max(worst, deviation)
            advance_state(law, q, p, state, agents, dt, lambda: pair_sums(law, q, p, edges), t)
            for key, value in agents.state.items():
                problem = output_problem(law, f'state {key!r}', value, value.shape)
                if problem is not None:
                    raise AssertionError(f'step {k} (t = {t:g} s): {problem}')
            q, p = step_agents(q, p, u, dt, intrinsic)
            leader.step(dt)
    return {'steps': count, 'agents': n, 'largest_local_deviation': worst}


def _check_step(law, q, p, edges, state, agents, dt: float, t: float, halves):
    """Return ``u`` of one step and the largest relative deviation of an agent alone.

    :raises AssertionError: for a non-finite ``u``, a container's rows that differ from the
        swarm's, or an agent alone beyond :data:`LOCAL_RTOL`.
    """
    import numpy as np

    from flock_swarm.core.laws.evaluation import (group_control, local_control, output_problem,
                                                  swarm_control)

    u = swarm_control(law, q, p, edges, state, agents, dt, t)
    problem = output_problem(law, 'combine()', u, q.shape)
    if problem is not None:
        raise AssertionError(problem)
    for ids in halves:
        if ids.size and not np.array_equal(
                group_control(law, ids, q, p, edges, state, agents.subset(ids), dt, t), u[ids]):
            raise AssertionError(f'{law.name}: group_control of agents {ids[0]}..{ids[-1]} '
                                 '(a container) differs from swarm_control (sim)')
    scale = float(np.abs(u).max()) or 1.0
    worst = 0.0
    for i in range(q.shape[0]):
        nb, w = _neighbours(edges, i)
        alone = local_control(law, q[i], p[i], q[nb], p[nb], w, state,
                              agents.subset(np.array([i])), dt, t)
        deviation = float(np.abs(alone - u[i]).max()) / scale
        worst = max(worst, deviation)
        if not deviation <= LOCAL_RTOL:
            raise AssertionError(f'{law.name}: agent {i} alone (local_control) gives '
                                 f'{alone.tolist()}, the swarm (swarm_control) {u[i].tolist()}')
    return u, worst


def _neighbours(edges, i: int):
    """Return agent ``i``'s neighbours and the weights of the edges to them."""
    import numpy as np
    as_i, as_j = edges.i == i, edges.j == i
    return (np.concatenate((edges.j[as_i], edges.i[as_j])),
            np.concatenate((edges.weight[as_i], edges.weight[as_j])))


def _law_scenario(law) -> dict:
    """Return the scenario :func:`check_law` runs a bare law in (see :data:`CHECK_STEPS`)."""
    import dataclasses
    import math

    protocol = {'name': law.name}
    for f in dataclasses.fields(law):
        if f.init:
            value = getattr(law, f.name)
            protocol[f.name] = _as_yaml(value)
    size = law.radius if math.isfinite(law.radius) and law.radius > 0 else 1.0
    return {'name': f'check_{law.name}', 'dim': 2, 'n_agents': 8, 'dt': 0.01,
            'duration': CHECK_STEPS * 0.01, 'seed': 0, 'protocol': protocol,
            'informed': {'select': 'first', 'count': 4},
            'initial': {'position_box': [[0.0, size], [0.0, size]],
                        'velocity_box': [[-1.0, 1.0], [-1.0, 1.0]]},
            'leader': {'model': 'constant_velocity', 'position': [size / 2, size / 2],
                       'velocity': [1.0, 0.0]}}


def _as_yaml(value: Any) -> Any:
    """Return a law field as YAML would give it (tuples as lists)."""
    if isinstance(value, tuple):
        return [_as_yaml(v) for v in value]
    return value


# -- the pytest plugin -----------------------------------------------------------------------

def pytest_configure(config) -> None:
    """Refuse, before any test, a ``$FLOCK_SWARM_TEST_DOMAINS`` the fixtures cannot use: one
    line naming the variable and exit status 2, instead of an error in every ROS test."""
    try:
        domain_ranges(os.environ.get(DOMAINS_VARIABLE))
    except ValueError as err:
        pytest.exit(f'error: {err}', returncode=2)


@pytest.fixture
def ros_domain(monkeypatch) -> int:
    """Return a ROS domain id unique to this test (:func:`unique_domain`).

    Unless the environment says otherwise, DDS discovery is limited to this machine for the
    test (``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``).
    """
    if DISCOVERY_RANGE not in os.environ:
        monkeypatch.setenv(DISCOVERY_RANGE, LOCALHOST)
    domain = unique_domain()
    yield domain
    # Held only while the test runs: a long test session would otherwise hold every id, and
    # the processes its tests start would find none free.
    release_domain(domain)


@pytest.fixture
def other_ros_domain(ros_domain: int) -> int:
    """Return a second domain id for the same test, different from :func:`ros_domain`'s."""
    domain = unique_domain()
    yield domain
    release_domain(domain)


@pytest.fixture
def ros_context(ros_domain: int):
    """Return an initialised ``rclpy`` context of its own on the test's domain id (shut down
    after the test), for nodes a test creates itself."""
    import rclpy
    from rclpy.context import Context

    from flock_swarm.nodes.spin import middleware_defaults
    context = Context()
    middleware_defaults()
    rclpy.init(context=context, domain_id=ros_domain)
    yield context
    rclpy.try_shutdown(context=context)


@pytest.fixture
def flock_swarm_run(tmp_path: Path, ros_domain: int) -> Callable[..., SwarmRun]:
    """Return ``run(scenario, overrides=(), **args)``: :func:`run_swarm` on the test's domain.

    Each call writes to a directory of its own under ``tmp_path`` (``run0``, ``run1``...).
    """
    calls = itertools.count()

    def run(scenario: str | Path, overrides: Iterable[str] = (), **args) -> SwarmRun:
        args.setdefault('domain_id', ros_domain)
        return run_swarm(scenario, tmp_path / f'run{next(calls)}', overrides, **args)

    return run


@pytest.fixture
def in_process_swarm(tmp_path: Path, ros_domain: int) -> Iterator[Callable[..., Swarm]]:
    """Return ``start(scenario, overrides=(), **args)``: a :class:`Swarm` on the test's domain.

    Each swarm writes to a directory of its own under ``tmp_path`` and is closed when the test
    ends, whatever happened.
    """
    started: list[Swarm] = []

    def start(scenario: str | Path, overrides: Iterable[str] = (), **args) -> Swarm:
        args.setdefault('domain_id', ros_domain)
        started.append(Swarm(scenario, tmp_path / f'swarm{len(started)}', overrides, **args))
        return started[-1]

    yield start
    for swarm in started:
        swarm.close()
