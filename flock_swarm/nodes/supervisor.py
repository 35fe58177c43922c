"""Supervision of a run's processes, as ``ros2 launch`` supervises its own.

:func:`flock_swarm.nodes.swarm_runner.run_processes` (``swarm --processes``) starts the leader,
the agents and the world through a :class:`Supervisor`, which

- writes each child's stdout and stderr to ``OUT/logs/<name>.log`` (``world.log``,
  ``leader.log``, ``agents.log`` or ``agent_<i>.log``), the world's also to this process's
  stderr (its progress lines);
- watches every child while the world runs (:meth:`Supervisor.watch`): a child that exits
  before the world ended the run (a crash, a kill: any exit status but 0, which a leader or
  agent returns only after the world announced the end) ends the run: the world is sent
  :data:`~flock_swarm.console.FAIL_SIGNAL` and finalises its bag and summary with status
  ``failed``;
- on a stop signal of this process tells the world first (the same signal), waits for it to
  finalise, then stops the leader and the agents (:meth:`Supervisor.stop_all`). The world
  goes first so that the record ends with the last step every agent answered: agents
  stopped first would leave the world waiting out a step timeout and recording zero
  commands, counted as missed, that no agent failed to send.

Every wait is bounded (:data:`FINALISE_TIMEOUT`, :data:`STOP_TIMEOUT`); what is still there
after it is killed, so no child outlives the supervisor.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from pathlib import Path
import signal
import subprocess
import sys
import threading
import time
from typing import Callable, IO

from flock_swarm.console import FAIL_SIGNAL

#: The run's log directory, in its output directory.
LOG_DIR = 'logs'
#: Seconds the world gets to finalise its bag and summary once told to stop, before it is
#: killed (the time series of a long run is assembled then: about 1 s a million rows here).
FINALISE_TIMEOUT = 120.0
#: Seconds the leader and the agents get to exit after a SIGINT, before they are killed.
STOP_TIMEOUT = 10.0
#: Lines of a dead child's log that are printed.
TAIL_LINES = 20
#: Seconds between two looks at the children.
POLL = 0.1
#: Seconds after which a signal is sent to a world that does not catch it yet (a Python
#: process catches none until its main installs the handlers, a second or two after start).
HANDLER_WAIT = 30.0


@dataclass
class Child:
    """A process of the run.

    :ivar name: its name (that of its log: ``world``, ``leader``, ``agents``, ``agent_3``).
    :ivar proc: the process.
    :ivar log: its log file.
    """

    name: str
    proc: subprocess.Popen
    log: Path

    def exit_text(self) -> str:
        """Return how it exited: ``exited with status 1`` or ``was killed by SIGKILL``."""
        code = self.proc.returncode
        if code is not None and code < 0:
            return f'was killed by {signal.Signals(-code).name}'
        return f'exited with status {code}'

    def tail(self, lines: int = TAIL_LINES) -> list[str]:
        """Return the last ``lines`` lines of its log."""
        try:
            with open(self.log, errors='replace') as text:
                return [line.rstrip('\n') for line in deque(text, maxlen=lines)]
        except OSError:
            return []


@dataclass
class Outcome:
    """How the world's run ended, as the supervisor saw it.

    :ivar signal: the stop signal forwarded to the world, or ``None``.
    :ivar dead: the child whose death ended the run, or ``None``.
    :ivar timed_out: whether the run outlived its wall-clock limit.
    :ivar killed: whether the world was killed (it did not finalise in time).
    """

    signal: int | None = None
    dead: Child | None = None
    timed_out: bool = False
    killed: bool = False


class Supervisor:
    """Start, log, watch and stop the processes of one run.

    :param logs: the log directory (created).
    :param env: the children's environment.
    """

    def __init__(self, logs: Path, env: dict) -> None:
        """Create the log directory."""
        self.logs = Path(logs)
        self.logs.mkdir(parents=True, exist_ok=True)
        self.env = env
        self.children: list[Child] = []
        self._tees: list[threading.Thread] = []

    def start(self, name: str, command: list[str], echo: IO[str] | None = None) -> Child:
        """Start ``command`` as the child ``name``, its output to ``logs/<name>.log``.

        :param echo: a stream that gets the output too, line by line (the world's progress).
        """
        path = self.logs / f'{name}.log'
        with open(path, 'w') as log:
            if echo is None:
                proc = subprocess.Popen(command, env=self.env, stdout=log,
                                        stderr=subprocess.STDOUT)
            else:
                proc = subprocess.Popen(command, env=self.env, stdout=subprocess.PIPE,
                                        stderr=subprocess.STDOUT)
                tee = threading.Thread(target=_tee, args=(proc.stdout, path, echo),
                                       name=f'log-{name}', daemon=True)
                tee.start()
                self._tees.append(tee)
        child = Child(name, proc, path)
        self.children.append(child)
        return child

    def watch(self, world: Child, stop: Callable[[], int | None],
              timeout: float | None = None) -> Outcome:
        """Wait for the world to end its run, ending it early when needed; return how.

        :param world: the world's child.
        :param stop: returns the stop signal this process received, or ``None``.
        :param timeout: wall-clock limit [s] of the run (``None``: none); past it the world
            is stopped with SIGINT.
        """
        outcome = Outcome()
        started = time.monotonic()
        limit = None if timeout is None else started + timeout
        told_at = None
        while True:
            try:
                world.proc.wait(timeout=POLL)
                break
            except subprocess.TimeoutExpired:
                pass
            now = time.monotonic()
            if told_at is not None:
                if now - told_at > FINALISE_TIMEOUT:
                    world.proc.kill()
                    outcome.killed = True
                continue
            sig = stop()
            dead = next((c for c in self.children
                         if c is not world and c.proc.poll() not in (None, 0)), None)
            if (sig is not None or dead is not None) and not _ready(world, started):
                # Sent before the world installed its handlers, the signal would kill it
                # without a summary: it is sent once the world catches it.
                continue
            if sig is not None:
                outcome.signal = sig
                world.proc.send_signal(sig)
            elif dead is not None:
                outcome.dead = dead
                world.proc.send_signal(FAIL_SIGNAL)
            elif limit is not None and now > limit:
                outcome.timed_out = True
                world.proc.send_signal(signal.SIGINT)
            else:
                continue
            told_at = now
        for tee in self._tees:
            tee.join(timeout=STOP_TIMEOUT)
        return outcome

    def stop_all(self, timeout: float = STOP_TIMEOUT) -> None:
        """Stop every child still running, the world last (see the module's docstring), with
        :func:`stop`."""
        stop([c.proc for c in self.children if c.name != 'world']
             + [c.proc for c in self.children if c.name == 'world'], timeout)


def stop(procs: list[subprocess.Popen], timeout: float = STOP_TIMEOUT) -> None:
    """End processes as Ctrl-C would (SIGINT), killing those still there after ``timeout``.

    One deadline for all: a hundred agent processes that ignore SIGINT are killed after
    ``timeout``, not after ``timeout`` each.
    """
    for proc in procs:
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
    deadline = time.monotonic() + timeout
    for proc in procs:
        try:
            proc.wait(timeout=max(0.0, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def catches(pid: int, sig: int) -> bool | None:
    """Return whether process ``pid`` catches signal ``sig`` (``None``: cannot tell, no
    ``/proc``), from the ``SigCgt`` mask of ``/proc/PID/status``."""
    try:
        with open(f'/proc/{pid}/status') as status:
            for line in status:
                if line.startswith('SigCgt:'):
                    return bool(int(line.split()[1], 16) >> (int(sig) - 1) & 1)
    except (OSError, ValueError, IndexError):
        return None
    return None


def _ready(world: Child, started: float) -> bool:
    """Return whether the world takes signals now: it catches FAIL_SIGNAL and SIGTERM (its
    main installed its handlers), it cannot be told, or it was given :data:`HANDLER_WAIT`."""
    if time.monotonic() - started > HANDLER_WAIT:
        return True
    return all(catches(world.proc.pid, sig) is not False
               for sig in (FAIL_SIGNAL, signal.SIGTERM))


def _tee(stream: IO[bytes], path: Path, echo: IO[str]) -> None:
    """Copy ``stream`` line by line to the file ``path`` (appended) and to ``echo``."""
    with open(path, 'ab', buffering=0) as log:
        for line in stream:
            log.write(line)
            try:
                echo.write(line.decode(errors='replace'))
                echo.flush()
            except (OSError, ValueError):
                # The terminal went away (SIGHUP): the log still gets every line.
                pass
    stream.close()


def report_death(child: Child, step, say: Callable[[str], None] = None) -> None:
    """Print that ``child`` died during the run (one line naming it), then its log's tail.

    :param child: the dead child.
    :param step: the step the run ended at (the world's summary), or ``None``.
    :param say: where the lines go (default: stderr).
    """
    at = '' if step is None else f' at step {step}'
    report_exit(child, f'during the run; the world ended the run as failed{at}', say)


def report_exit(child: Child, what: str, say: Callable[[str], None] = None) -> None:
    """Print one line naming ``child``, how it exited and ``what`` followed, then the tail of
    its log (or that its log is empty: the line no longer ends in a colon with nothing after).

    :param child: the child that exited.
    :param what: what its exit meant, after how it exited (``during the run; ...``).
    :param say: where the lines go (default: stderr).
    """
    say = say or (lambda line: print(line, file=sys.stderr, flush=True))
    tail = child.tail()
    where = (f'the last lines of {child.log}:' if tail
             else f'its log {child.log} is empty')
    say(f'swarm: error: {child.name} (pid {child.proc.pid}) {child.exit_text()} {what}; '
        f'{where}')
    for line in tail:
        say(f'  | {line}')
