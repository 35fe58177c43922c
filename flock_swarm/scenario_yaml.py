"""Scenario YAML: the loader every scenario file, sweep spec and ``--set`` value goes through.

The io layer's half of the scenario (:mod:`flock_swarm.core.scenario` is the schema and
imports no YAML): PyYAML's safe loader with YAML 1.2 floats, bounded aliases and no duplicate
keys, the reading of a YAML file as one-line errors, and the ``dotted.key=value`` overrides
of ``--set``, ROS parameters and sweep points.
"""

import copy
import re
from pathlib import Path
from typing import Any

import yaml
from yaml.nodes import MappingNode, Node, SequenceNode

from flock_swarm.core.errors import ScenarioError

#: Most nodes that aliases (``*name``) may add to a document when expanded. Anchors and
#: aliases share one object in the parsed value, but every later step (validation, the
#: scenario as run written to JSON, an error message) expands them: nine nested levels of ten
#: aliases (a "billion laughs") are 10**9 values from a few hundred bytes. No scenario needs
#: more than a few aliases of small nodes; explicit positions of many agents need none.
MAX_ALIAS_NODES = 10_000
_MERGE_TAG = 'tag:yaml.org,2002:merge'


class RefusedYAML(yaml.MarkedYAMLError):
    """Well-formed YAML that the loader refuses: a duplicate key, aliases that expand too far."""


class ScenarioLoader(yaml.SafeLoader):
    """PyYAML's safe loader, reading YAML 1.2 floats, with bounded aliases and unique keys.

    PyYAML follows YAML 1.1, where an exponent needs a dot (``1.0e-3``); ``1e-3`` would
    otherwise arrive as the string ``'1e-3'``. A document whose aliases would expand to more
    than :data:`MAX_ALIAS_NODES` further nodes, or that refers to itself, is refused after it
    is composed and before any value is built (nothing is expanded to find out). A key given
    twice in one mapping is refused (PyYAML would keep the last one silently); keys merged
    with ``<<`` may be overridden, as YAML's merge means.
    """

    def compose_document(self) -> Node:
        """Compose a document and refuse it when its aliases expand too far."""
        self._first_alias = None
        node = super().compose_document()
        sizes: dict[int, int] = {}
        expanded = _expanded_size(node, sizes, set(), self._first_alias)
        added = expanded - len(sizes)
        if added > MAX_ALIAS_NODES:
            raise RefusedYAML(None, None, f'aliases would expand the document by {added} '
                              f'nodes (at most {MAX_ALIAS_NODES}); refused',
                              self._first_alias or node.start_mark)
        return node

    def compose_node(self, parent: Node | None, index: Any) -> Node:
        """Compose a node, remembering where the first alias is (for the error's line)."""
        if self._first_alias is None and self.check_event(yaml.AliasEvent):
            self._first_alias = self.peek_event().start_mark
        return super().compose_node(parent, index)

    def construct_mapping(self, node: MappingNode, deep: bool = False) -> dict:
        """Build a mapping, refusing a key given twice."""
        if isinstance(node, MappingNode):
            seen = set()
            for key_node, _ in node.value:
                if key_node.tag == _MERGE_TAG:
                    continue
                key = self.construct_object(key_node, deep=True)
                try:
                    duplicate = key in seen
                    seen.add(key)
                except TypeError:
                    continue  # an unhashable key: the base class reports it
                if duplicate:
                    raise RefusedYAML('while constructing a mapping', node.start_mark,
                                      f'duplicate key {key!r} (a key may be given once)',
                                      key_node.start_mark)
        return super().construct_mapping(node, deep=deep)


def _expanded_size(node: Node, sizes: dict[int, int], active: set[int], mark: Any) -> int:
    """Return how many nodes ``node`` stands for with every alias expanded.

    Each distinct node is visited once (``sizes`` by ``id``), so the cost is that of the
    document as written, however far its aliases would expand.

    :raises RefusedYAML: for a node that contains itself.
    """
    key = id(node)
    if key in sizes:
        return sizes[key]
    if key in active:
        raise RefusedYAML(None, None, 'an alias refers to a node that contains it; refused',
                          mark or node.start_mark)
    active.add(key)
    size = 1
    if isinstance(node, SequenceNode):
        size += sum(_expanded_size(item, sizes, active, mark) for item in node.value)
    elif isinstance(node, MappingNode):
        size += sum(_expanded_size(k, sizes, active, mark) + _expanded_size(v, sizes, active,
                                                                            mark)
                    for k, v in node.value)
    active.discard(key)
    sizes[key] = size
    return size


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


def yaml_problem(exc: yaml.YAMLError) -> str:
    """Return ``invalid YAML at line N`` for an error of :func:`parse_yaml`, with the reason
    when the loader refused well-formed YAML (a duplicate key, aliases expanding too far)."""
    mark = getattr(exc, 'problem_mark', None)
    where = f' at line {mark.line + 1}' if mark is not None else ''
    why = f': {exc.problem}' if isinstance(exc, RefusedYAML) else ''
    return f'invalid YAML{where}{why}'


def read_yaml_file(path: Path, key: str, kind: str) -> Any:
    """Read a YAML file (a scenario, a sweep spec) with :func:`parse_yaml`.

    :param path: the file.
    :param key: the name errors give the file (``scenario``, ``spec``).
    :param kind: what the file is, for the message on a binary file (``a scenario``).
    :return: the parsed value.
    :raises ScenarioError: for a file that cannot be read, is not UTF-8 text (a binary file,
        say) or is not YAML the loader accepts.
    """
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise ScenarioError(key, f'{path}: {exc.strerror}') from None
    try:
        # utf-8-sig: a byte order mark, as some editors write it, is not part of the text.
        text = raw.decode('utf-8-sig')
    except UnicodeDecodeError as exc:
        raise ScenarioError(key, f'{path}: not UTF-8 text (byte 0x{raw[exc.start]:02x} '
                            f'at offset {exc.start}); {kind} is a YAML file') from None
    try:
        return parse_yaml(text)
    except yaml.YAMLError as exc:
        raise ScenarioError(key, f'{path}: {yaml_problem(exc)}') from None


def parse_value(text: str) -> Any:
    """Parse the value of a ``--set key=value`` override as YAML (``0.5``, ``[1, 2]``, ``true``).

    :param text: the value text.
    :return: the parsed value.
    """
    try:
        return parse_yaml(text)
    except yaml.YAMLError as exc:
        why = getattr(exc, 'problem', None) or exc
        # The start of a long value is enough to recognise it, and leaves room for the why.
        shown = repr(text) if len(text) <= 80 else f'{text[:60]!r}...'
        raise ScenarioError('--set', f'cannot parse value {shown}: {why}') from None


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
