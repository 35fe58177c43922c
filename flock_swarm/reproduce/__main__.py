"""``python -m flock_swarm.reproduce``: run the reproduction and write its report."""

import sys

from flock_swarm.cli.reproduce import main

if __name__ == '__main__':
    sys.exit(main())
