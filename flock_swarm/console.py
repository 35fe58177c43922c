"""The console side of every executable: exit statuses, one-line argument errors, signals.

Shared by the commands (:mod:`flock_swarm.cli`) and the node executables (their ``main`` in
:mod:`flock_swarm.nodes`): a neutral module that libraries may import, so that no library
imports a command module.

The exit statuses are one table for every executable (docs/ros.md, "Signals and exit
statuses"): 0 done, 1 the run failed, 2 invalid input, and ``128 + n`` when the stop signal
``n`` ended it (:data:`EXIT_SIGNAL`). :class:`StopSignals` is how an executable catches the
stop signals so that it finalises what it was writing before it exits with that status.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
import tempfile
from pathlib import Path
from types import FrameType
from typing import Iterator

from flock_swarm.core.errors import one_line

#: Exit status when the run failed: a node, a child process or the recording failed, a law or
#: leader model faulted, the state stopped being finite (``sim``), or ``analyze --verify``
#: found the recording off the simulation. The one name of status 1 in the package.
EXIT_FAILURE = 1
#: Exit status for invalid input (as argparse uses), of every command and node of the package.
EXIT_USAGE = 2
#: The signals that stop a run cleanly: Ctrl-C, ``kill`` (and a supervisor such as
#: ``ros2 launch`` escalating), and the terminal closing.
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
#: The exit status after each stop signal, the same for every command and node: 128 plus the
#: signal's number, as a shell reports a process that signal ended (130, 143, 129), so a
#: script sees the same status whether the process finalised its outputs or was killed.
EXIT_SIGNAL = {sig: 128 + int(sig) for sig in STOP_SIGNALS}
#: Exit status after Ctrl-C (SIGINT).
EXIT_INTERRUPTED = EXIT_SIGNAL[signal.SIGINT]
#: What a supervisor (``swarm --processes``) sends the world when one of the run's other
#: processes died: the world ends the run with status ``failed`` and exits with
#: :data:`EXIT_FAILURE`. No stop signal: the run did not end because somebody asked.
FAIL_SIGNAL = signal.SIGUSR1
#: Exit status of a command whose machinery failed while it ran, its input being valid (a
#: sweep's Dask scheduler lost, no Dask workers): running it again may succeed.
EXIT_RUNTIME = 3


#: The distribution whose console scripts are the executables (setup.py's ``name``).
DISTRIBUTION = 'flock-swarm'
#: The package of the commands' modules (``flock_swarm.cli.<name>``).
COMMAND_PACKAGE = 'flock_swarm.cli'


def executables() -> dict[str, str]:
    """Return every executable of the package, name to ``module:function``: the console
    scripts of setup.py's entry points, as installed (the one list of them)."""
    from importlib.metadata import distribution
    return {ep.name: ep.value for ep in distribution(DISTRIBUTION).entry_points
            if ep.group == 'console_scripts'}


def commands() -> dict[str, str]:
    """Return the commands (``sim``, ``swarm``...): the executables whose module is in
    :data:`COMMAND_PACKAGE`, name to module; the others are node executables."""
    return {name: target.split(':')[0] for name, target in executables().items()
            if target.startswith(COMMAND_PACKAGE + '.')}


#: Where the runs of this machine hold their ROS domains (:func:`claim_domain`): one file per
#: id, ``<id>.run``, beside the test processes' ``<id>.lock`` (a different hold).
DOMAIN_LOCKS = Path(tempfile.gettempdir()) / 'flock_swarm_domains'


class DomainBusy(Exception):
    """Another run of this machine holds the ROS domain; the message is one line."""


def claim_domain(domain: int, command: str) -> object | None:
    """Hold ROS domain ``domain`` for a run of this process, or refuse: one run per domain.

    Two runs on one domain mix their messages (a second world zeroes every command while its
    agents follow the first world's clock): ``swarm`` and ``replay --clock`` hold the domain
    for as long as they run, with a lock on ``DOMAIN_LOCKS/<id>.run`` (released when the
    returned file is closed, or the process ends, however it ends), and a second one is
    refused at once. Discovery is limited to this machine (``scripts/env.sh``), so the
    machine's lock files cover every run that can meet; a world started by hand is still
    refused by the world itself (docs/ros.md, "One world per domain").

    :param domain: the ROS domain id.
    :param command: who holds it (written into the file for the refusal of the next one).
    :return: the open lock file (close it to release the domain), or ``None`` when no lock
        file can be made here (nothing held, nothing refused).
    :raises DomainBusy: when another process holds the domain.
    """
    import fcntl
    try:
        DOMAIN_LOCKS.mkdir(exist_ok=True)
        lock = open(DOMAIN_LOCKS / f'{domain}.run', 'a+', encoding='utf-8')
    except OSError:
        return None
    try:
        fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        lock.seek(0)
        holder = ' '.join(lock.read().split()) or 'another process'
        lock.close()
        raise DomainBusy(f'domain {domain} is in use by a run of this machine ({holder}): '
                         'give each run a domain of its own') from None
    lock.seek(0)
    lock.truncate()
    lock.write(f'{command}, pid {os.getpid()}\n')
    lock.flush()
    return lock


class OneLineParser(argparse.ArgumentParser):
    """An argument parser whose errors are one line naming the option, like scenario errors.

    ``sim: error: --seed: invalid int value: 'x'`` instead of argparse's usage block followed
    by ``sim: error: argument --seed: ...``; exit status 2 as argparse's.
    """

    def error(self, message: str):
        """Print ``PROG: error: OPTION: reason (see PROG --help)`` and exit with status 2."""
        required = 'the following arguments are required: '
        unknown = 'unrecognized arguments: '
        if message.startswith('argument '):
            message = message[len('argument '):]
        elif message.startswith(required):
            message = f'{message[len(required):]}: required'
        elif message.startswith(unknown):
            message = f'{message[len(unknown):]}: unrecognized argument(s)'
        self.exit(EXIT_USAGE, f'{self.prog}: error: {one_line(message)} (see {self.prog} '
                  '--help)\n')


def out_dir(text: str) -> Path:
    """Return the path of an ``--out`` option; an empty one is refused.

    ``Path('')`` is the current directory: ``--out ''`` (an unset shell variable, say) would
    write the outputs among whatever is there.

    :raises argparse.ArgumentTypeError: for an empty (or all-blank) text.
    """
    if not text.strip():
        raise argparse.ArgumentTypeError('must name a directory, got an empty path')
    return Path(text)


def accept_sigint() -> None:
    """Let SIGINT stop this process (and the processes it starts) as Ctrl-C would.

    A non-interactive shell starts background jobs (``cmd &`` in a script) with SIGINT
    ignored; Python then raises no ``KeyboardInterrupt``, and every child inherits the
    ignored signal. A ``world`` started so could not be stopped cleanly (its bag closed),
    and :func:`flock_swarm.nodes.supervisor.stop` would wait out its timeout on every node
    before killing it (seen: a benchmark of 50 agent processes took 20 s per process to tear
    down). Restores Python's default handler when, and only when, SIGINT is ignored.
    """
    if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)


def signal_name(sig: int) -> str:
    """Return the name of signal ``sig`` (``SIGTERM``)."""
    return signal.Signals(sig).name


class StopSignals:
    """Catch the stop signals (:data:`STOP_SIGNALS`) while a ``with`` block runs.

    Without it SIGTERM and SIGHUP end a Python process at once, leaving half-written outputs
    (a bag without its index, temporary files), and only SIGINT raises
    ``KeyboardInterrupt``. Within the block each stop signal is noted in :attr:`received`
    and, with ``interrupt``, raises ``KeyboardInterrupt`` as SIGINT does, so code that stops
    cleanly on Ctrl-C stops the same way on each of them; :meth:`held` notes them only, while
    outputs are written. Leaving the block restores the previous handlers.

    A signal ignored when the block is entered stays ignored (``nohup`` ignores SIGHUP so
    the process survives the terminal), except SIGINT: see :func:`accept_sigint`.

    :param interrupt: raise ``KeyboardInterrupt`` on each stop signal (else only note it).
    """

    def __init__(self, interrupt: bool = False) -> None:
        """Create the catcher (installed by ``with``)."""
        self.interrupt = interrupt
        #: The stop signals received, in order.
        self.received: list[int] = []
        self._previous: dict[int, object] = {}
        self._holding = 0

    def __enter__(self) -> StopSignals:
        """Install the handlers; return the catcher."""
        accept_sigint()
        for sig in STOP_SIGNALS:
            if signal.getsignal(sig) != signal.SIG_IGN:
                self._previous[sig] = signal.signal(sig, self._handle)
        return self

    def __exit__(self, *exc_info) -> None:
        """Restore the previous handlers."""
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)
        self._previous = {}

    def _handle(self, number: int, frame: FrameType | None) -> None:
        self.received.append(number)
        if self.interrupt and not self._holding:
            raise KeyboardInterrupt

    @contextlib.contextmanager
    def held(self) -> Iterator[StopSignals]:
        """Note stop signals only, within the ``with`` block (while outputs are written)."""
        self._holding += 1
        try:
            yield self
        finally:
            self._holding -= 1

    @property
    def stopped(self) -> bool:
        """Whether a stop signal came."""
        return bool(self.received)

    @property
    def first(self) -> int | None:
        """The first stop signal received (the one the exit status tells), or ``None``."""
        return self.received[0] if self.received else None

    def status(self, otherwise: int = 0) -> int:
        """Return the exit status: :data:`EXIT_SIGNAL` of the first signal, else ``otherwise``."""
        return otherwise if not self.received else EXIT_SIGNAL[self.received[0]]
