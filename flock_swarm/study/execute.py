"""Running a sweep's runs: stacks, records, the cache, progress, and where the work goes.

The runs still missing from the cache are grouped into jobs (stacks of realisations run side
by side by :func:`simulate_stack`), and the jobs go to a backend: this process
(:class:`SerialBackend`), local worker processes (:class:`LocalPool`) or a Dask cluster
(:class:`DaskBackend`). Every backend runs the same jobs through the same :func:`run_job`,
so the records are the same bit for bit; each finished job's records reach the cache file
before the next result is taken, so an interrupted sweep keeps every finished run.
"""

import multiprocessing
import signal
import sys
import time
import traceback
from collections import deque
from contextlib import closing
from dataclasses import dataclass
from multiprocessing.connection import wait
from pathlib import Path
from typing import Any, Callable, Iterator

import numpy as np

from flock_swarm import __version__
from flock_swarm.core import summary
from flock_swarm.core.run import RunResult, simulate_stack
from flock_swarm.core.scenario import Scenario
from flock_swarm.outputs import plain_json
from flock_swarm.study.cache import CacheWriter, read_cache
from flock_swarm.study.spec import Run, metric_value, timed_column

#: Without a terminal, progress lines come at most this often [s] (on one, a live line).
PROGRESS_EVERY = 30.0
#: A job whose worker process dies this many times is given up (it kills its worker).
MAX_WORKER_DEATHS = 3
#: How long to wait for a Dask scheduler to answer, and for a worker when it has none [s].
CONNECT_TIMEOUT = 10.0
#: How often the Dask backend looks at its scheduler and workers while it waits [s].
DASK_POLL = 1.0

#: A record maker: ``(run, scenario, result) -> record`` (a module-level function or a
#: picklable object, so that worker processes and Dask workers can receive it).
Recorder = Callable[[Run, Scenario, RunResult], dict]


class SweepError(RuntimeError):
    """A failure of the sweep's machinery (a backend, a worker), one line."""


class ClusterError(SweepError):
    """The Dask cluster became unusable while the sweep ran: the scheduler lost, no workers.

    Not the user's input: ``sweep`` exits with its runtime-failure status, and running it
    again (with the cache of the runs finished so far) may succeed.
    """


@dataclass(frozen=True)
class Job:
    """Runs executed together in one stack, and their cost in agent-steps."""

    runs: tuple[Run, ...]

    @property
    def weight(self) -> int:
        """Return the job's cost in agent-steps."""
        return sum(r.weight for r in self.runs)


def make_jobs(runs: list[Run], stack_agents: int) -> list[Job]:
    """Group runs into jobs: consecutive runs of one stack key, stacked.

    Each group of consecutive runs sharing a stack key is split into stacks of about
    ``stack_agents // N`` runs (at least one), of sizes as equal as possible; the runs'
    order is kept. A run without a stack key is a job of its own.

    :param runs: the runs to do, in plan order.
    :param stack_agents: about how many agents a stack holds.
    :return: the jobs.
    """
    groups: list[list[Run]] = []
    for run in runs:
        if groups and run.stack_key is not None and groups[-1][0].stack_key == run.stack_key:
            groups[-1].append(run)
        else:
            groups.append([run])
    jobs = []
    for group in groups:
        per_stack = max(1, stack_agents // group[0].n_agents)
        count = -(-len(group) // per_stack)
        for part in np.array_split(np.arange(len(group)), count):
            jobs.append(Job(tuple(group[k] for k in part.tolist())))
    return jobs


def run_job(job: Job, recorder: Recorder) -> list[dict]:
    """Run a job's realisations in one stack and return their records (in the job's order).

    :param job: the runs.
    :param recorder: makes a run's record from its scenario and result.
    :return: one record per run, each with its ``digest``.
    """
    scenarios = [run.scenario() for run in job.runs]
    results = simulate_stack(scenarios)
    return [{**recorder(run, sc, res), 'digest': run.digest}
            for run, sc, res in zip(job.runs, scenarios, results)]


@dataclass(frozen=True)
class MetricRecorder:
    """The record of a run of ``sweep``: point, seed, metrics (also at times), provenance."""

    metrics: tuple[str, ...]
    times: tuple[float, ...] = ()

    def __call__(self, run: Run, sc: Scenario, result: RunResult) -> dict:
        """Return the record (non-finite values as ``None``)."""
        s, series = result.summary, result.series
        record: dict[str, Any] = {'point': plain_json(run.point), 'seed': run.seed}
        for name in self.metrics:
            record[name] = plain_json(metric_value(s, name))
        if self.times:
            t, timed = series['t'], summary.timed_series()
            for when in self.times:
                # The first recorded instant at or after `when` (half a step of slack).
                k = min(int(np.searchsorted(t, when - 0.5 * sc.dt)), len(t) - 1)
                for name in self.metrics:
                    if name in timed:
                        record[timed_column(name, when)] = plain_json(series[timed[name]][k])
        record.update(status=s['status'], wall_time_s=s['wall_time_s'],
                      flock_swarm_version=__version__)
        return record


class Progress:
    """Progress of a sweep: runs done / total, elapsed time and the time left.

    The time left extrapolates the rate of agent-steps done so far (runs of 1000 agents
    cost about ten times those of 100). On a terminal (``live``) one line is rewritten in
    place after every job; otherwise ``say`` gets a line at most every ``every`` seconds
    and after the last job.
    """

    def __init__(self, total: int, weight: float, say: Callable[[str], None],
                 live: Callable[[str], None] | None = None,
                 every: float = PROGRESS_EVERY, prefix: str = 'sweep') -> None:
        """Start the clock.

        :param total: runs to do.
        :param weight: their total cost in agent-steps.
        :param say: where progress lines go.
        :param live: rewrites the terminal's current line, or ``None`` (no terminal).
        :param every: seconds between lines without a terminal.
        :param prefix: the tool's name at the start of each line.
        """
        self.total, self.weight, self.say, self.live, self.every = total, weight, say, live, every
        self.prefix = prefix
        self.started = self.last = time.monotonic()
        self.done, self.done_weight = 0, 0.0

    def step(self, runs: int, weight: float, text: str) -> None:
        """Report a finished job of ``runs`` runs costing ``weight`` agent-steps."""
        self.done += runs
        self.done_weight += weight
        now = time.monotonic()
        elapsed = now - self.started
        left = elapsed / max(self.done_weight, 1e-9) * (self.weight - self.done_weight)
        width = 24
        filled = int(width * self.done_weight / max(self.weight, 1e-9))
        line = (f'[{self.prefix}] [{"#" * filled}{"." * (width - filled)}] '
                f'{self.done}/{self.total} runs  elapsed {elapsed / 60:.1f} min  '
                f'ETA {left / 60:.1f} min  ({text})')
        finished = self.done >= self.total
        if self.live is not None:
            self.live(line + ('\n' if finished else ''))
        elif finished or now - self.last >= self.every:
            self.last = now
            self.say(line)


def terminal_line(line: str) -> None:
    """Rewrite the current line of the terminal on stderr (a live progress bar)."""
    sys.stderr.write('\r\x1b[K' + line)
    sys.stderr.flush()


class SerialBackend:
    """Runs every task in this process, in order."""

    name = 'this process'

    def results(self, func: Callable[..., Any], tasks: list, *args) -> Iterator[tuple]:
        """Yield ``(task, func(task, *args))`` for every task."""
        for task in tasks:
            yield task, func(task, *args)

    def close(self) -> None:
        """Nothing to release."""


class LocalPool:
    """Worker processes on this machine; a task whose worker dies is given to another.

    ``spawn`` workers (the parent may hold ROS (DDS) threads, which ``fork`` would copy),
    each fed one task at a time through its own pipe, so the parent always knows which task
    a worker holds: when a worker process dies (killed, out of memory), its task goes back
    to the queue and a new worker starts. Workers ignore SIGINT: Ctrl-C reaches the parent,
    which stops them (finished runs are already in the cache).
    """

    def __init__(self, jobs: int, say: Callable[[str], None] | None = None) -> None:
        """Prepare a pool of ``jobs`` workers (started on first use).

        :param jobs: worker processes.
        :param say: told when a worker dies and its task is redone.
        """
        self.jobs, self.say = jobs, say
        self.name = f'{jobs} local worker process{"es" if jobs > 1 else ""}'
        self.ctx = multiprocessing.get_context('spawn')

    def results(self, func: Callable[..., Any], tasks: list, *args) -> Iterator[tuple]:
        """Yield ``(task, func(task, *args))`` for every task, in completion order."""
        queue = deque(range(len(tasks)))
        deaths = [0] * len(tasks)
        busy: dict[Any, tuple[Any, int]] = {}
        idle: list[tuple[Any, Any]] = []
        try:
            while queue or busy:
                while queue and (idle or len(busy) < self.jobs):
                    proc, conn = idle.pop() if idle else self._start(func, args)
                    try:
                        conn.send(tasks[queue[0]])
                    except OSError:
                        # It died while idle: it held no task; another worker starts.
                        proc.join()
                        conn.close()
                        continue
                    busy[conn] = (proc, queue.popleft())
                ready = wait(list(busy) + [proc.sentinel for proc, _ in busy.values()])
                for conn in list(busy):
                    proc, k = busy[conn]
                    if conn in ready or conn.poll():
                        try:
                            status, value = conn.recv()
                        except (EOFError, OSError):
                            status = 'died'
                    elif proc.sentinel in ready:
                        status = 'died'
                    else:
                        continue
                    del busy[conn]
                    if status == 'died':
                        proc.join()
                        deaths[k] += 1
                        if deaths[k] >= MAX_WORKER_DEATHS:
                            raise SweepError(f'a job killed {deaths[k]} worker processes '
                                             f'(last exit code {proc.exitcode}); giving up')
                        if self.say is not None:
                            self.say(f'[sweep] worker process {proc.pid} died (exit code '
                                     f'{proc.exitcode}); its job is redone')
                        queue.appendleft(k)
                        conn.close()
                        continue
                    idle.append((proc, conn))
                    if status == 'error':
                        raise SweepError(f'a worker failed: {value}')
                    yield tasks[k], value
        finally:
            for proc, conn in idle + [(p, c) for c, (p, _) in busy.items()]:
                if proc.is_alive():
                    proc.terminate()
                proc.join()
                conn.close()

    def _start(self, func: Callable[..., Any], args: tuple) -> tuple[Any, Any]:
        """Start one worker; return it and the parent's end of its pipe."""
        mine, theirs = self.ctx.Pipe()
        proc = self.ctx.Process(target=_worker, args=(theirs, func, args), daemon=True)
        proc.start()
        theirs.close()
        return proc, mine

    def close(self) -> None:
        """Nothing left running between calls of :meth:`results`."""


def _worker(conn, func: Callable[..., Any], args: tuple) -> None:
    """Run tasks received on ``conn`` until the parent closes it; send back each result."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    while True:
        try:
            task = conn.recv()
        except (EOFError, OSError):
            return
        try:
            conn.send(('ok', func(task, *args)))
        except Exception as exc:  # any failure: reported to the parent, which stops the sweep
            last = traceback.extract_tb(exc.__traceback__)[-1]
            conn.send(('error', f'{type(exc).__name__}: {exc} ({Path(last.filename).name}:'
                                f'{last.lineno})'))


class DaskBackend:
    """A Dask distributed cluster: a scheduler's address, or ``local`` (a LocalCluster).

    Workers need only this package installed (the same version, so that the digests
    match). Dask reschedules the tasks of a worker that dies.
    """

    def __init__(self, address: str, jobs: int, timeout: float = CONNECT_TIMEOUT) -> None:
        """Connect (or start a local cluster of ``jobs`` single-threaded workers).

        :param address: the scheduler's address (``tcp://host:8786``) or ``local``.
        :param jobs: workers of a local cluster.
        :param timeout: seconds to wait for the scheduler.

        :raises SweepError: naming the address when the scheduler cannot be reached.
        """
        import logging
        from distributed import Client, LocalCluster
        # The connection error (and a lost scheduler) is reported as one line below, not as
        # Dask's log records (its loggers have levels of their own from Dask's config).
        for name in ['distributed', *logging.root.manager.loggerDict]:
            if name.startswith('distributed'):
                logging.getLogger(name).setLevel(logging.CRITICAL)
        self.cluster = None
        self.address, self.timeout = address, timeout
        try:
            if address == 'local':
                self.cluster = LocalCluster(n_workers=jobs, threads_per_worker=1,
                                            processes=True, dashboard_address=None,
                                            host='127.0.0.1')
                self.client = Client(self.cluster)
            else:
                self.client = Client(address, timeout=timeout)
        except (OSError, TimeoutError, ValueError) as exc:
            raise SweepError(f'--scheduler: cannot reach {address}: '
                             f'{str(exc).splitlines()[0] if str(exc) else type(exc).__name__}'
                             ) from None
        workers = len(self.client.scheduler_info().get('workers', {}))
        self.name = f'Dask scheduler {self.client.scheduler.address} ({workers} worker(s) now)'

    def results(self, func: Callable[..., Any], tasks: list, *args) -> Iterator[tuple]:
        """Yield ``(task, func(task, *args))`` for every task, in completion order.

        Waits at most :data:`DASK_POLL` seconds at a time, so that a scheduler lost (its
        futures cancelled, the client no longer running) or a cluster without a worker for
        the connection timeout ends the sweep with one :class:`ClusterError` line instead of
        a traceback or a silent wait.

        :raises ClusterError: the scheduler lost, or no worker for ``timeout`` seconds.
        :raises SweepError: a task that failed.
        """
        from distributed import wait as dask_wait
        futures = []
        for k, task in enumerate(tasks):
            # Earlier tasks first (the plan puts long runs first); pure=False: always run.
            futures.append(self.client.submit(func, task, *args, pure=False,
                                              priority=len(tasks) - k))
        index = {fut.key: k for k, fut in enumerate(futures)}
        pending = dict(index)
        idle_since = None
        try:
            while pending:
                waiting = [futures[k] for k in pending.values()]
                try:
                    done = dask_wait(waiting, timeout=DASK_POLL,
                                     return_when='FIRST_COMPLETED').done
                except TimeoutError:
                    done = set()
                except Exception:  # futures cancelled: by a lost scheduler, or by Dask
                    done = set()
                    self._check_scheduler(len(tasks) - len(pending), len(tasks))
                for fut in (f for f in waiting if f in done):
                    try:
                        value = fut.result()
                    except Exception as exc:  # a task's failure: one line, the sweep stops
                        self._check_scheduler(len(tasks) - len(pending), len(tasks))
                        raise SweepError(f'a Dask task failed: {type(exc).__name__}: {exc}') \
                            from None
                    del pending[fut.key]
                    yield tasks[index[fut.key]], value
                self._check_scheduler(len(tasks) - len(pending), len(tasks))
                if self.client.scheduler_info().get('workers'):
                    idle_since = None
                elif idle_since is None:
                    idle_since = time.monotonic()
                elif time.monotonic() - idle_since >= self.timeout:
                    raise ClusterError(f'--scheduler: no Dask worker for {self.timeout:g} s at '
                                       f'{self.address} ({len(tasks) - len(pending)} of '
                                       f'{len(tasks)} jobs done, kept in the cache); start '
                                       'workers and run the same command again')
        finally:
            if pending and self.client.status == 'running':
                self.client.cancel([futures[k] for k in pending.values()])

    def _check_scheduler(self, done: int, total: int) -> None:
        """Raise :class:`ClusterError` when the client lost its scheduler."""
        if self.client.status != 'running':
            raise ClusterError(f'--scheduler: lost the Dask scheduler at {self.address} '
                               f'({done} of {total} jobs done, kept in the cache); run the same '
                               'command again to go on')

    def close(self) -> None:
        """Disconnect (and stop the local cluster); a lost scheduler is not waited for."""
        try:
            self.client.close(timeout=self.timeout)
        except Exception:  # already closed by a lost scheduler: nothing to release
            pass
        if self.cluster is not None:
            self.cluster.close()


def execute(runs: list[Run], cache_path: Path, recorder: Recorder, backend,
            stack_agents: int, say: Callable[[str], None],
            live: Callable[[str], None] | None = None, fresh: bool = False,
            prefix: str = 'sweep', describe: Callable[[Job, list[dict]], str] | None = None
            ) -> dict:
    """Run every run not in the cache; return all records in plan order and what ran.

    :param runs: the plan.
    :param cache_path: the JSON-lines cache (created; appended to).
    :param recorder: makes each run's record.
    :param backend: where jobs run (:class:`SerialBackend`, :class:`LocalPool`,
        :class:`DaskBackend`).
    :param stack_agents: about how many agents a stack holds.
    :param say: progress and cache reports.
    :param live: rewrites the terminal's progress line, or ``None``.
    :param fresh: ignore (and replace) the cache.
    :param prefix: the tool's name in progress lines.
    :param describe: the text of a finished job's progress line.
    :return: ``{'records': [...], 'executed': n, 'cached': n, 'core_seconds': s}``.
    :raises KeyboardInterrupt: on Ctrl-C, after every finished run reached the cache.
    """
    if fresh and cache_path.exists():
        cache_path.unlink()
    records = read_cache(cache_path, ('digest', 'status'), say)
    todo = [r for r in runs if r.digest not in records]
    jobs = make_jobs(todo, stack_agents)
    cached = len(runs) - len(todo)
    say(f'[{prefix}] {len(runs)} runs: {len(todo)} to run in {len(jobs)} stacks, {cached} '
        f'reused from {cache_path}; on {backend.name}')
    progress = Progress(len(todo), sum(j.weight for j in jobs), say, live, prefix=prefix)
    core = 0.0
    interrupted = False
    # closing(): an interrupt while a result is handled here still stops the workers.
    with CacheWriter(cache_path) as cache, \
            closing(backend.results(run_job, jobs, recorder)) as results:
        for job, recs in results:
            # JSON types, non-finite values as None: the record as the cache gives it back.
            done = [plain_json(r) for r in recs if r['status'] != 'interrupted']
            interrupted |= len(done) < len(recs)
            cache.add(done)
            for rec in done:
                records[rec['digest']] = rec
                core += rec['wall_time_s']
            text = describe(job, recs) if describe is not None else _describe(job, recs)
            progress.step(len(job.runs), job.weight, text)
            if interrupted:
                raise KeyboardInterrupt
    return {'records': [records[r.digest] for r in runs if r.digest in records],
            'executed': len(todo), 'cached': cached, 'core_seconds': core}


def _describe(job: Job, recs: list[dict]) -> str:
    """Return the default progress text of a finished job."""
    point = ', '.join(f'{k} = {v}' for k, v in job.runs[0].point.items())
    stacked = f', {len(job.runs)} stacked' if len(job.runs) > 1 else ''
    return f'{point or "run"} seed {job.runs[0].seed}{stacked}: ' \
        f'{sum(r["wall_time_s"] for r in recs):.1f} s'
