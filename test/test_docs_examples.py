"""Every ``sim``, ``sweep``, ``swarm``, ``analyze`` and ``replay`` line of the docs runs.

The command lines of the fenced ``bash`` blocks of README.md and docs/*.md are run, block by
block in the order of the document, in a temporary directory of the document's own (so that
``analyze out/demo_ros/bag`` finds the bag ``swarm ... --out out/demo_ros`` recorded above
it). ``ros2 run flock_swarm CMD`` and ``python -m flock_swarm.cli.CMD`` run as ``CMD``, the
console script of the same entry point; other lines (``source``, ``colcon``, the nodes) are
not commands of this test.

A block is marked by an HTML comment on the line before it, invisible on a rendered page:

- ``<!-- examples: not run (REASON) -->``: none of the block's lines runs (a Dask cluster, a
  live viewer, a loop until Ctrl-C, a file of the reader's own);
- ``<!-- examples: ARGS -->``: ``ARGS`` is appended to the block's ``sim``, ``sweep`` and
  ``swarm`` lines, to shorten long runs (``--set duration=0.5``: the last ``--set`` wins);
- no comment: the lines run as written.

A line that runs again (``ros2 run`` or ``python -m`` of a line above) runs once. Each line
must exit with status 0 and no traceback.
"""

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

from flock_swarm.console import commands

ROOT = Path(__file__).resolve().parent.parent
BIN = Path(sys.executable).parent
DOCS = [ROOT / 'README.md', *sorted((ROOT / 'docs').glob('*.md'))]
#: The commands whose example lines run: setup.py's console scripts into flock_swarm.cli.
COMMANDS = tuple(commands())
#: Commands that get a block's ARGS.
SHORTENED = ('sim', 'sweep', 'swarm')
MARK = re.compile(r'^<!-- examples: (.*) -->$')
FENCE = re.compile(r'^```(\w*)$')


def command(line: str) -> list[str] | None:
    """Return the argv of an example line of one of :data:`COMMANDS`, or ``None``."""
    try:
        argv = shlex.split(line, comments=True)
    except ValueError:
        return None
    if argv[:3] == ['ros2', 'run', 'flock_swarm']:
        argv = argv[3:]
    elif argv[:2] == ['python', '-m'] and len(argv) > 2 \
            and argv[2].startswith('flock_swarm.cli.'):
        argv = [argv[2].rsplit('.', 1)[1], *argv[3:]]
    return argv if argv and argv[0] in COMMANDS else None


def examples(doc: Path) -> tuple[list[list[str]], list[list[str]]]:
    """Return the example command lines of a document: those to run, those marked not run."""
    run, skipped = [], []
    lines = doc.read_text().splitlines()
    mark, inside, lang, pending = None, False, '', ''
    for k, line in enumerate(lines):
        fence = FENCE.match(line.strip())
        if fence and not inside:
            inside, lang = True, fence.group(1)
            before = next((p.strip() for p in reversed(lines[:k]) if p.strip()), '')
            found = MARK.match(before)
            mark = found.group(1).strip() if found else None
            continue
        if fence and inside:
            inside = False
            continue
        if not inside or lang != 'bash':
            continue
        if line.rstrip().endswith('\\'):
            pending += line.rstrip()[:-1] + ' '
            continue
        argv = command(pending + line)
        pending = ''
        if argv is None:
            continue
        if mark is not None and mark.startswith('not run'):
            skipped.append(argv)
        else:
            extra = shlex.split(mark) if mark and argv[0] in SHORTENED else []
            if argv + extra not in run:  # the same line again (ros2 run, python -m)
                run.append(argv + extra)
    return run, skipped


def test_the_examples_are_found():
    """The extraction sees the examples the issue names, and every mark is well-formed."""
    found = {doc.name: examples(doc) for doc in DOCS}
    assert ['sweep', 'su2009_fig3', '--seeds', '2', '--set', 'duration=10', '--set',
            'duration=0.2'] in found['README.md'][0]
    assert ['sweep', 'su2009_fig3', '--seeds', '2', '--set', 'duration=10', '--set',
            'duration=0.2'] in found['sweeps.md'][0]
    assert any(argv[0] == 'analyze' for argv in found['analysis.md'][0])
    for doc in DOCS:
        for line in doc.read_text().splitlines():
            if line.startswith('<!-- examples'):
                assert MARK.match(line), f'{doc.name}: malformed mark {line!r}'


@pytest.mark.parametrize('doc', [d for d in DOCS if examples(d)[0]], ids=lambda d: d.name)
def test_every_example_runs(doc, tmp_path, ros_domain):
    env = dict(os.environ, ROS_DOMAIN_ID=str(ros_domain), PYTHONUNBUFFERED='1')
    for argv in examples(doc)[0]:
        res = subprocess.run([str(BIN / argv[0]), *argv[1:]], cwd=tmp_path, env=env,
                             capture_output=True, text=True, timeout=300)
        shown = shlex.join(argv)
        assert res.returncode == 0, f'{doc.name}: {shown}: {res.stderr}'
        assert 'Traceback' not in res.stderr, f'{doc.name}: {shown}: {res.stderr}'
