"""The resumable run cache of a sweep: one JSON line per finished run, keyed by its digest.

Each line is a run's record plus ``check``, a hash of the rest of the line: a line cut short
by an interrupted write, edited by hand or damaged on disk fails to parse or to match its
check, is reported, and its run is done again; it is never used. The digest (see
:func:`~flock_swarm.study.spec.scenario_digest`) hashes the scenario as run and the package
version, so a changed scenario or a new version runs anew.
"""

import hashlib
import json
import os
from pathlib import Path
from typing import Callable, Iterable


def _check(record: dict) -> str:
    """Return the check of a record (without its ``check`` field)."""
    text = json.dumps({k: v for k, v in record.items() if k != 'check'}, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def cache_line(record: dict) -> str:
    """Return a record as one checked cache line (with its newline)."""
    return json.dumps({**record, 'check': _check(record)}, allow_nan=False) + '\n'


def read_cache(path: Path, required: Iterable[str] = ('digest',),
               report: Callable[[str], None] | None = None) -> dict[str, dict]:
    """Return the valid records of a cache file by digest (the last one of a digest wins).

    Unusable lines are reported once: they are moved out of the cache, to
    ``PATH.unusable`` (kept for a look), so that the next read (of this run or a later one)
    does not report them again; their runs are redone.

    :param path: the JSON-lines file (absent: no records).
    :param required: keys every record must have.
    :param report: told one line per line that is unusable (and whose run is redone).
    :return: ``{digest: record}``, each without its ``check``.
    """
    records: dict[str, dict] = {}
    if not path.is_file():
        return records
    need = tuple(required)
    kept: list[bytes] = []
    unusable: list[bytes] = []
    with open(path, 'rb') as stream:
        for number, raw in enumerate(stream, 1):
            why = None
            try:
                rec = json.loads(raw.decode())
            except (UnicodeDecodeError, ValueError):
                why = 'not a complete JSON line (an interrupted write?)'
            else:
                if not isinstance(rec, dict):
                    why = 'not a record'
                elif rec.get('check') != _check(rec):
                    why = 'its check does not match its content'
                elif any(k not in rec for k in need):
                    why = f'no {next(k for k in need if k not in rec)!r}'
            if why is not None:
                if raw.strip():
                    unusable.append(raw if raw.endswith(b'\n') else raw + b'\n')
                    if report is not None:
                        report(f'{path}:{number}: unusable cache line ({why}); its run is '
                               'redone')
                continue
            kept.append(raw)
            del rec['check']
            records[rec['digest']] = rec
    if unusable:
        _set_aside(path, kept, unusable, report)
    return records


def _set_aside(path: Path, kept: list[bytes], unusable: list[bytes],
               report: Callable[[str], None] | None) -> None:
    """Rewrite the cache with the ``kept`` lines only; append ``unusable`` to PATH.unusable."""
    aside = path.with_name(path.name + '.unusable')
    try:
        with open(aside, 'ab') as stream:
            stream.write(b''.join(unusable))
        partial = path.with_name(path.name + '.partial')
        with open(partial, 'wb') as stream:
            stream.write(b''.join(line if line.endswith(b'\n') else line + b'\n'
                                  for line in kept))
            stream.flush()
            os.fsync(stream.fileno())
        os.replace(partial, path)
    except OSError as exc:  # a read-only cache: the lines are reported again next time
        if report is not None:
            report(f'{path}: cannot set the unusable lines aside to {aside} ({exc.strerror})')


class CacheWriter:
    """Appends records to a cache file, each on disk before :meth:`add` returns."""

    def __init__(self, path: Path) -> None:
        """Open ``path`` for appending (created with its directory).

        A last line without its newline (a write cut short) is ended first, so that the next
        record starts a line of its own.
        """
        path.parent.mkdir(parents=True, exist_ok=True)
        self.stream = open(path, 'ab')
        if self.stream.tell():
            with open(path, 'rb') as old:
                old.seek(-1, os.SEEK_END)
                if old.read(1) != b'\n':
                    self.stream.write(b'\n')

    def add(self, records: Iterable[dict]) -> None:
        """Append records and flush them to disk (a crash after this keeps them)."""
        self.stream.write(''.join(cache_line(r) for r in records).encode())
        self.stream.flush()
        os.fsync(self.stream.fileno())

    def close(self) -> None:
        """Close the file."""
        self.stream.close()

    def __enter__(self) -> 'CacheWriter':
        """Return the writer."""
        return self

    def __exit__(self, *exc) -> None:
        """Close the file."""
        self.close()
