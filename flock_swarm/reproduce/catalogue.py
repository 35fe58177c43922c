"""The catalogue of experiments: every module of :mod:`flock_swarm.reproduce.experiments`
that holds an ``EXPERIMENT`` (an :class:`~flock_swarm.reproduce.experiment.Experiment`),
plus any registered with :func:`register`, in the report's order.

Adding an experiment is adding one module to that package (``docs/reproduction/README.md``,
"Adding an experiment"); nothing else names it.
"""

import importlib
import pkgutil

#: The packages searched for experiment modules.
PACKAGES = ('flock_swarm.reproduce.experiments',)

_REGISTERED: list = []


def discover(package: str) -> list:
    """Return the ``EXPERIMENT`` of every module of ``package`` (modules without one, such as
    shared helpers, are skipped).

    :param package: a package's import name.
    """
    pkg = importlib.import_module(package)
    found = []
    for info in pkgutil.iter_modules(pkg.__path__, f'{package}.'):
        exp = getattr(importlib.import_module(info.name), 'EXPERIMENT', None)
        if exp is not None:
            found.append(exp)
    return found


def register(experiment):
    """Add an experiment defined outside the searched packages; return it.

    :param experiment: an :class:`~flock_swarm.reproduce.experiment.Experiment`.
    """
    _REGISTERED.append(experiment)
    return experiment


def all_experiments() -> tuple:
    """Return every experiment in the report's order (``order``, then ``key``).

    :raises ValueError: when two experiments share a key.
    """
    found = [e for package in PACKAGES for e in discover(package)] + _REGISTERED
    seen: set[str] = set()
    for exp in found:
        if exp.key in seen:
            raise ValueError(f'two experiments named {exp.key!r}')
        seen.add(exp.key)
    return tuple(sorted(found, key=lambda e: (e.order, e.key)))


def experiment(key: str):
    """Return the experiment named ``key``.

    :raises KeyError: when there is none.
    """
    for exp in all_experiments():
        if exp.key == key:
            return exp
    raise KeyError(key)
