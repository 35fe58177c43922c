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
import math
import os
import time
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator, TYPE_CHECKING

import pytest

from flock_swarm.core.summary import sim_only_keys

if TYPE_CHECKING:
    import numpy as np

    from flock_swarm.bag import BagReader
    from flock_swarm.core.scenario import Scenario

#: Wall-clock bound [s] of one whole run when the caller gives none (a hung run fails).
RUN_TIMEOUT = 240.0
#: The environment variable that limits DDS discovery, and the value the fixtures default to:
#: a test never talks to, or hears from, another host.
DISCOVERY_RANGE = 'ROS_AUTOMATIC_DISCOVERY_RANGE'
LOCALHOST = 'LOCALHOST'
#: Domain ids handed out: [1, DOMAIN_SPAN]. Domain 0 is everybody's default, and ids above
#: are left to the demo and to people's own runs.
DOMAIN_SPAN = 200
#: The poll interval [s] of :func:`wait_for`.
POLL = 0.05
#: Keys of ``sim``'s summary that are not the swarm's but the simulator's own: its wall time,
#: and its count of pseudo-leader reselections (the world does not keep one); from the table
#: of summary keys (:mod:`flock_swarm.core.summary`, which imports no NumPy).
SIM_ONLY = sim_only_keys()

_domains = itertools.count()


def unique_domain() -> int:
    """Return a ROS domain id not handed out before in this process, in [1, 200].

    Ids are spread over the range by process id, so two test processes on one machine are
    unlikely to collide (200 ids a process before one repeats).
    """
    return 1 + (os.getpid() * 37 + next(_domains)) % DOMAIN_SPAN


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


class SwarmRun:
    """What a finished run left in its output directory, read back from the files.

    :param out: the run's output directory (``summary.json``, ``timeseries.npz``, ``bag/``).
    :raises AssertionError: when the run wrote no ``summary.json``.
    """

    def __init__(self, out: Path) -> None:
        """Read the scenario and the summary the run wrote."""
        from flock_swarm.core.scenario import parse_scenario, parse_yaml

        self.out = Path(out)
        summary = self.out / 'summary.json'
        if not summary.is_file():
            raise AssertionError(f'the run wrote no {summary}')
        #: The ``summary.json`` mapping.
        self.summary: dict = json.loads(summary.read_text())
        #: The resolved scenario file every node ran on.
        self.scenario_path = self.out / 'scenario.yaml'
        #: The validated scenario.
        self.scenario: Scenario = parse_scenario(parse_yaml(self.scenario_path.read_text()))

    def timeseries(self) -> dict[str, np.ndarray]:
        """Return the recorded time series (``timeseries.npz``) as arrays."""
        import numpy as np

        with np.load(self.out / 'timeseries.npz') as data:
            return {name: data[name] for name in data.files}

    def bag(self) -> BagReader:
        """Return a reader of the recorded bag (:class:`flock_swarm.bag.BagReader`).

        :raises AssertionError: when the run recorded no bag (``record: False``).
        """
        from flock_swarm.bag import BagReader

        if not (self.out / 'bag').is_dir():
            raise AssertionError(f'the run recorded no bag in {self.out / "bag"}')
        return BagReader(self.out / 'bag')

    def messages(self, topics: Iterable[str] | str) -> list:
        """Return the messages of ``topics`` in the bag as ``(BagMessage, rclpy message)``."""
        return list(self.bag().decoded(topics))


class Swarm:
    """World, leader and agents spinning in this process: a context manager for tests.

    A thin layer over :class:`flock_swarm.runner.InProcessSwarm` (``swarm`` without
    ``--processes``): the scenario is resolved as ``swarm`` resolves it (a preset name or a
    path, with ``key=value`` overrides) into ``out/scenario.yaml``; waits are bounded and fail
    with a message; the outputs are read back as a :class:`SwarmRun`. Every attribute of the
    in-process swarm (``world``, ``leader``, ``agents``, ``executor``, ``context``, ``add``,
    ``add_leader``, ``add_agents``, ``remove``) is reachable on this object.

    :param scenario: a preset name or a scenario file.
    :param out: the output directory (created).
    :param overrides: ``key=value`` assignments, as ``swarm --set``.
    :param seed: a seed replacing the scenario's, or ``None``.
    :param domain_id: the ROS domain id (``None``: :func:`unique_domain`).
    :param swarm_args: further arguments of :class:`~flock_swarm.runner.InProcessSwarm`
        (``mode``, ``step_timeout``, ``executor``, ``agents``, ``world_params``,
        ``agent_params``, ``realtime_factor``, ``progress``).
    """

    def __init__(self, scenario: str | Path, out: Path, overrides: Iterable[str] = (),
                 seed: int | None = None, domain_id: int | None = None,
                 **swarm_args) -> None:
        """Resolve the scenario and start every node."""
        from flock_swarm.runner import InProcessSwarm, resolve_scenario

        self.out = Path(out)
        self.domain_id = unique_domain() if domain_id is None else domain_id
        self.scenario_path = resolve_scenario(str(scenario), list(overrides), seed, self.out)
        #: The :class:`~flock_swarm.runner.InProcessSwarm` this wraps.
        self.in_process = InProcessSwarm(self.scenario_path, self.out,
                                         domain_id=self.domain_id, **swarm_args)
        self.closed = False

    def __getattr__(self, name: str):
        """Reach the in-process swarm's nodes and methods (``swarm.world``...)."""
        if name == 'in_process':
            raise AttributeError(name)
        return getattr(self.in_process, name)

    def spin_until(self, condition: Callable[[], Any], timeout: float,
                   what: str = 'the condition') -> None:
        """Spin every node until ``condition`` holds.

        :param condition: checked after every callback (or every 0.1 s without one).
        :param timeout: wall-clock bound [s].
        :param what: what is awaited, for the failure message.
        :raises AssertionError: on the timeout, or when the world finished first.
        """
        world = self.in_process.world
        deadline = time.monotonic() + timeout
        while not condition():
            if world.done:
                raise AssertionError(f'the run ended ({world.status} at step {world.k}) '
                                     f'before {what}')
            if time.monotonic() > deadline:
                raise AssertionError(f'timed out after {timeout:g} s waiting for {what} '
                                     f'(the world is at step {world.k})')
            self.in_process.executor.spin_once(timeout_sec=0.1)

    def run(self, timeout: float = RUN_TIMEOUT) -> SwarmRun:
        """Spin until the world has recorded its last step; close; return the outputs.

        :param timeout: wall-clock bound [s] of the rest of the run.
        """
        world = self.in_process.world
        self.spin_until(lambda: world.done, timeout, 'the world to finish')
        self.close()
        return self.result()

    def result(self) -> SwarmRun:
        """Return the outputs (once the world finished, or after :meth:`close`)."""
        return SwarmRun(self.out)

    def close(self) -> None:
        """Let the world write what it recorded; destroy every node and the context (once)."""
        if not self.closed:
            self.closed = True
            self.in_process.close()

    def __enter__(self) -> Swarm:
        """Return the swarm."""
        return self

    def __exit__(self, *exc_info) -> None:
        """Close the swarm."""
        self.close()


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
    float arrays may differ by ``atol`` (0: bit for bit), everything else must be equal.

    :param want: the reference summary.
    :param want_series: the reference time series.
    :param got: the summary compared with it.
    :param got_series: the time series compared with it.
    :param atol: the absolute tolerance.
    :return: one line per difference.
    """
    import numpy as np

    problems = [f'summary {line}' for line in _differences('', want, got, atol)]
    for name, ref in want_series.items():
        if name not in got_series:
            problems.append(f'series {name}: missing')
            continue
        ref, value = np.asarray(ref), np.asarray(got_series[name])
        if ref.shape != value.shape:
            problems.append(f'series {name}: shape {value.shape}, want {ref.shape}')
        elif ref.dtype.kind == 'f' or value.dtype.kind == 'f':
            diff = np.abs(value.astype(float) - ref.astype(float))
            bad = (diff > atol) | (np.isnan(value) != np.isnan(ref))
            if bad.any():
                first = np.unravel_index(int(np.argmax(bad)), bad.shape)
                problems.append(f'series {name}: {int(bad.sum())} of {bad.size} values differ '
                                f'by more than {atol:g} (max {float(np.nanmax(diff)):.3g}, '
                                f'first at index {tuple(int(i) for i in first)})')
        elif not np.array_equal(ref, value):
            problems.append(f'series {name}: {int((ref != value).sum())} values differ')
    return problems


def _differences(where: str, want: Any, got: Any, atol: float) -> Iterator[str]:
    """Yield ``key: got X, want Y`` for every leaf of ``want`` that ``got`` does not match."""
    if isinstance(want, dict):
        for key, value in want.items():
            path = f'{where}.{key}' if where else key
            if not isinstance(got, dict) or key not in got:
                yield f'{path}: missing'
            else:
                yield from _differences(path, value, got[key], atol)
    elif isinstance(want, list) and isinstance(got, list) and len(want) == len(got):
        for i, (a, b) in enumerate(zip(want, got)):
            yield from _differences(f'{where}[{i}]', a, b, atol)
    elif (isinstance(want, float) and isinstance(got, (int, float))
          and not isinstance(got, bool)):
        if not (abs(got - want) <= atol or got == want
                or (math.isnan(got) and math.isnan(want))):
            yield f'{where}: got {got!r}, want {want!r} (atol {atol:g})'
    elif want != got:
        yield f'{where}: got {got!r}, want {want!r}'


def assert_matches_sim(scenario: str | Path, out: Path, overrides: Iterable[str] = (),
                       seed: int | None = None, atol: float = 0.0,
                       domain_id: int | None = None, timeout: float = RUN_TIMEOUT,
                       **swarm_args) -> SwarmRun:
    """Run a scenario through the nodes (lockstep) and assert it equals ``sim``'s run.

    The summary (every key ``sim`` writes but :data:`SIM_ONLY`) and every recorded time series
    must agree to ``atol``; ``atol=0`` demands bit for bit. The ROS run must be complete:
    every agent answered every step and the leader was never missed (otherwise it is not the
    run ``sim`` computes, and the comparison would say nothing).

    :param atol: the absolute tolerance.
    :return: the ROS run's outputs.
    :raises AssertionError: listing every difference.

    The other parameters are :func:`run_swarm`'s.
    """
    from flock_swarm.core.run import simulate
    from flock_swarm.outputs import json_text

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


# -- the pytest plugin -----------------------------------------------------------------------

@pytest.fixture
def ros_domain(monkeypatch) -> int:
    """Return a ROS domain id unique to this test (:func:`unique_domain`).

    Unless the environment says otherwise, DDS discovery is limited to this machine for the
    test (``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``).
    """
    if DISCOVERY_RANGE not in os.environ:
        monkeypatch.setenv(DISCOVERY_RANGE, LOCALHOST)
    return unique_domain()


@pytest.fixture
def other_ros_domain(ros_domain: int) -> int:
    """Return a second domain id for the same test, different from :func:`ros_domain`'s."""
    return unique_domain()


@pytest.fixture
def ros_context(ros_domain: int):
    """Return an initialised ``rclpy`` context of its own on the test's domain id (shut down
    after the test), for nodes a test creates itself."""
    import rclpy
    from rclpy.context import Context
    context = Context()
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
