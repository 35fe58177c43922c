"""Command-line plumbing shared by the package's tools (``sim``, ``swarm``, ``analyze`` ...)."""

import argparse

#: Exit status for invalid input (as argparse uses).
EXIT_USAGE = 2


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
        self.exit(EXIT_USAGE, f'{self.prog}: error: {message} (see {self.prog} --help)\n')
