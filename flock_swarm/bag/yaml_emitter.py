"""The YAML of a bag's ``metadata.yaml``: rosbag2's layout (yaml-cpp's), written fast.

:func:`dump_yaml` writes plain mappings, lists and scalars itself, each distinct scalar's
text PyYAML's, so the whole text is PyYAML's with :class:`_RosbagDumper` character for
character (tested); anything else goes to PyYAML whole.
"""

import re
from typing import Any

import yaml


class _RosbagDumper(yaml.SafeDumper):
    """A YAML dumper whose output looks like yaml-cpp's, which rosbag2 uses."""

    def increase_indent(self, flow: bool = False, indentless: bool = False) -> None:
        # yaml-cpp indents a block sequence under its key; PyYAML would not.
        super().increase_indent(flow, False)


def _represent_str(dumper: yaml.SafeDumper, data: str) -> yaml.ScalarNode:
    if data == '':
        return dumper.represent_scalar('tag:yaml.org,2002:str', '', style='"')
    return dumper.represent_str(data)


def _represent_none(dumper: yaml.SafeDumper, data: None) -> yaml.ScalarNode:
    return dumper.represent_scalar('tag:yaml.org,2002:null', '~')


_RosbagDumper.add_representer(str, _represent_str)
_RosbagDumper.add_representer(type(None), _represent_none)


def _pyyaml_dump(data: Any) -> str:
    """Dump ``data`` with PyYAML and :class:`_RosbagDumper` (the reference layout)."""
    return yaml.dump(data, Dumper=_RosbagDumper, default_flow_style=False, sort_keys=False,
                     allow_unicode=True, width=1 << 16)


def dump_yaml(data: Any) -> str:
    """Dump data as block-style YAML in the layout of rosbag2's files, keys kept in order.

    The text is :class:`_RosbagDumper`'s (PyYAML) character for character; mappings, lists,
    strings, integers, booleans and ``None`` are laid out here directly (each distinct
    string's scalar is still PyYAML's), since PyYAML's pure-Python emitter took about 10 s
    for the metadata of a bag of 2000 topics (the world's at N = 1000, dumped twice on
    close). Anything else (a float, a string PyYAML would fold or break, a nested list)
    goes to PyYAML whole.

    :param data: plain dictionaries, lists, strings, numbers, booleans and ``None``.
    :return: the YAML text.
    """
    lines: list[str] = []
    try:
        if isinstance(data, dict) and data:
            _emit_mapping(data, '', lines)
        elif isinstance(data, list) and data:
            _emit_sequence(data, '', lines)
        else:
            raise _NotPlain
    except _NotPlain:
        return _pyyaml_dump(data)
    lines.append('')
    return '\n'.join(lines)


class _NotPlain(Exception):
    """Data :func:`dump_yaml` leaves to PyYAML."""


#: Strings PyYAML writes as one line whatever the column (no space to fold at, short).
_ONE_LINE = re.compile(r'[^\s]{0,1000}')
#: A scalar's text as a mapping value and as a key, by value (:func:`_scalar`, :func:`_key`).
_SCALARS: dict[str, str] = {}
_KEYS: dict[str, str] = {}


def _scalar(value: Any) -> str:
    """Return the text of a scalar as PyYAML writes it in block context."""
    kind = type(value)
    if kind is str:
        text = _SCALARS.get(value)
        if text is None:
            if not _ONE_LINE.fullmatch(value):
                raise _NotPlain
            dumped = _pyyaml_dump({'k': value})
            if not dumped.startswith('k: ') or dumped.count('\n') != 1:
                raise _NotPlain
            text = _SCALARS[value] = dumped[3:-1]
        return text
    if kind is bool:
        return 'true' if value else 'false'
    if kind is int:
        return str(value)
    if value is None:
        return '~'
    raise _NotPlain


def _key(key: Any) -> str:
    """Return the text of a mapping key as PyYAML writes it (a simple key)."""
    text = _KEYS.get(key)
    if text is None:
        if type(key) is not str or not key or not _ONE_LINE.fullmatch(key):
            raise _NotPlain
        dumped = _pyyaml_dump({key: 0})
        if not dumped.endswith(': 0\n') or dumped.count('\n') != 1:
            raise _NotPlain
        text = _KEYS[key] = dumped[:-4]
    return text


def _emit_mapping(data: dict, indent: str, lines: list[str], first: str | None = None) -> None:
    """Append a non-empty block mapping at ``indent``; ``first``: the prefix of its first line
    (a sequence item's ``- ``) instead of ``indent``."""
    for key, value in data.items():
        head = f'{indent if first is None else first}{_key(key)}:'
        first = None
        kind = type(value)
        if kind is dict:
            if value:
                lines.append(head)
                _emit_mapping(value, indent + '  ', lines)
            else:
                lines.append(head + ' {}')
        elif kind is list:
            if value:
                lines.append(head)
                _emit_sequence(value, indent + '  ', lines)
            else:
                lines.append(head + ' []')
        else:
            lines.append(f'{head} {_scalar(value)}')


def _emit_sequence(data: list, indent: str, lines: list[str]) -> None:
    """Append a non-empty block sequence at ``indent`` (items: non-empty mappings or
    scalars)."""
    for item in data:
        kind = type(item)
        if kind is dict:
            if not item:
                raise _NotPlain
            _emit_mapping(item, indent + '  ', lines, first=indent + '- ')
        elif kind is list:
            raise _NotPlain
        else:
            lines.append(f'{indent}- {_scalar(item)}')
