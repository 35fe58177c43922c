"""The console side of every executable: exit statuses, one-line argument errors, SIGINT.

Shared by the commands (:mod:`flock_swarm.cli`) and the node executables (their ``main`` in
:mod:`flock_swarm.nodes`): a neutral module that libraries may import, so that no library
imports a command module.
"""

import argparse
import signal
from pathlib import Path

from flock_swarm.core.errors import one_line

#: Exit status for invalid input (as argparse uses), of every command and node of the package.
EXIT_USAGE = 2
#: Exit status of a command whose machinery failed while it ran, its input being valid (a
#: sweep's Dask scheduler lost, no Dask workers): running it again may succeed.
EXIT_RUNTIME = 3
#: Exit status after Ctrl-C (as a shell reports SIGINT), of every command that catches it.
EXIT_INTERRUPTED = 130


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
    and :func:`flock_swarm.nodes.harness.stop` would wait out its timeout on every node
    before killing it (seen: a benchmark of 50 agent processes took 20 s per process to tear
    down). Restores Python's default handler when, and only when, SIGINT is ignored.
    """
    if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)
