"""Scenario YAML: the loader every scenario file and ``--set`` value goes through.

The io layer's half of the scenario (:mod:`flock_swarm.core.scenario` is the schema and
imports no YAML): PyYAML's safe loader with YAML 1.2 floats, and the ``dotted.key=value``
overrides of ``--set``, ROS parameters and sweep points.
"""

import copy
import re
from typing import Any

import yaml

from flock_swarm.core.errors import ScenarioError


class ScenarioLoader(yaml.SafeLoader):
    """PyYAML's safe loader, also reading YAML 1.2 floats such as ``1e-3`` as numbers.

    PyYAML follows YAML 1.1, where an exponent needs a dot (``1.0e-3``); ``1e-3`` would
    otherwise arrive as the string ``'1e-3'``.
    """


ScenarioLoader.add_implicit_resolver(
    'tag:yaml.org,2002:float',
    re.compile(r'^[-+]?(?:[0-9][0-9_]*)(?:\.[0-9_]*)?[eE][-+]?[0-9]+$'),
    list('-+0123456789'))


def parse_yaml(text: str) -> Any:
    """Parse YAML text with :class:`ScenarioLoader`.

    :param text: YAML text.
    :return: the parsed value.
    :raises yaml.YAMLError: on any malformed document.
    """
    try:
        return yaml.load(text, Loader=ScenarioLoader)
    except (ValueError, TypeError, AttributeError, OverflowError, RecursionError) as exc:
        # PyYAML's constructors raise these instead of a YAMLError for malformed tagged
        # scalars (``!!int abc``, ``!!timestamp 2001-13-45``), integers past Python's
        # 4300-digit conversion limit and nesting deeper than the interpreter's stack.
        raise yaml.YAMLError(f'{type(exc).__name__}: {exc}') from None


def parse_value(text: str) -> Any:
    """Parse the value of a ``--set key=value`` override as YAML (``0.5``, ``[1, 2]``, ``true``).

    :param text: the value text.
    :return: the parsed value.
    """
    try:
        return parse_yaml(text)
    except yaml.YAMLError as exc:
        why = getattr(exc, 'problem', None) or exc
        raise ScenarioError('--set', f'cannot parse value {text!r}: {why}') from None


def apply_override(data: dict, assignment: str) -> dict:
    """Return a copy of ``data`` with one ``dotted.key=value`` assignment applied.

    :param data: the scenario mapping.
    :param assignment: ``key=value``, e.g. ``protocol.c1=0.8`` or ``n_agents=20``.
    :return: the new mapping (the input is not modified).
    """
    if '=' not in assignment:
        raise ScenarioError('--set', f'expected key=value, got {assignment!r}')
    key, text = assignment.split('=', 1)
    key = key.strip()
    parts = key.split('.')
    if not all(parts):
        raise ScenarioError('--set', f'malformed key {key!r}')
    out = copy.deepcopy(data)
    node = out
    for depth, part in enumerate(parts[:-1]):
        child = node.get(part)
        if child is None:
            child = node[part] = {}
        if not isinstance(child, dict):
            raise ScenarioError('.'.join(parts[:depth + 1]), 'is not a section')
        node = child
    node[parts[-1]] = parse_value(text)
    return out
