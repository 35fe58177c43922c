"""Message definitions and type names, as rosbag2 stores them in an MCAP bag.

The schema of a channel is the full text of the type's ``.msg`` file followed by every type it
depends on, each under a two-line delimiter (``====...`` and ``MSG: pkg/Type``). This module
reproduces rosbag2's ``LocalMessageDefinitionSource`` (rosbag2_cpp, Jazzy) exactly:

- a ``.msg`` file is read from ``<share of pkg>/msg/<Type>.msg`` (ament index) and kept
  byte for byte, comments, constants and default values included;
- its dependencies are the non-primitive field types matched by rosbag2's regular expression,
  a bare ``Type`` meaning ``<same package>/Type``;
- dependencies are visited depth first in sorted (``std::set``) order, each written once;
- a type without a ``.msg`` file falls back to its ``.idl`` file (encoding ``ros2idl``).
"""

from dataclasses import dataclass
from functools import lru_cache
import importlib
import json
from pathlib import Path
import re

from ament_index_python.packages import get_package_share_directory, PackageNotFoundError

#: Schema encoding of a ``.msg`` based definition (MCAP well-known schema encoding).
ENCODING_MSG = 'ros2msg'
#: Schema encoding of an ``.idl`` based definition.
ENCODING_IDL = 'ros2idl'
#: Line that precedes every dependency block.
DELIMITER_LINE = '=' * 80
#: rosbag2's ROSBAG2_CPP_LOCAL_MESSAGE_DEFINITION_SOURCE_MAX_RECURSION_DEPTH.
MAX_RECURSION_DEPTH = 50

# rosbag2's MSG_FIELD_TYPE_REGEX and IDL_FIELD_TYPE_REGEX. ``^`` anchors at the start of the
# text only, as in std::regex without the multiline flag.
_MSG_FIELD_TYPE = re.compile(r'(?:^|\n)\s*([a-zA-Z0-9_/]+)(?:\[[^\]]*\])?\s+')
_IDL_INCLUDE = re.compile(r'(?:^|\n)#include\s+(?:"|<)([a-zA-Z0-9_/]+)\.idl(?:"|>)')
# rosbag2's PRIMITIVE_TYPES: anything else in type position is taken for a message type.
_PRIMITIVE_TYPES = frozenset({
    'bool', 'byte', 'char', 'float32', 'float64', 'int8', 'uint8', 'int16', 'uint16',
    'int32', 'uint32', 'int64', 'uint64', 'string'})
_ROS_NAME = '[a-zA-Z][a-zA-Z0-9_]*'
_TYPE_NAME = re.compile(rf'^({_ROS_NAME})/(?:({_ROS_NAME})/)?({_ROS_NAME})$')


class DefinitionNotFoundError(LookupError):
    """A type's definition file is not installed (unknown package or type)."""


@dataclass(frozen=True)
class MessageDefinition:
    """A channel schema: the type name, its encoding and the full definition text."""

    type_name: str
    encoding: str
    text: str


def split_type_name(type_name: str) -> tuple[str, str, str]:
    """Split ``pkg/msg/Type`` (or ``pkg/Type``) into package, namespace and type.

    :param type_name: a ROS 2 interface type name.
    :return: ``(package, namespace, type)``, namespace ``msg`` when the name has none.
    :raises ValueError: if the name is not of either form.
    """
    match = _TYPE_NAME.match(type_name)
    if match is None:
        raise ValueError(
            f"invalid message type name {type_name!r}: expected 'pkg/msg/Type' or 'pkg/Type'")
    package, namespace, name = match.groups()
    return package, namespace or 'msg', name


def type_name_of(msg_or_class: object) -> str:
    """Return the ``pkg/msg/Type`` name of a message, a message class or a type name string.

    :param msg_or_class: an rclpy message instance or class (``nav_msgs.msg.Odometry``), or a
        type name (``'nav_msgs/msg/Odometry'``, or ``'nav_msgs/Odometry'``).
    :return: the fully qualified name, for example ``'nav_msgs/msg/Odometry'``.
    :raises TypeError: if the argument is neither a ROS message nor a string.
    :raises ValueError: if a string is not a valid type name.
    """
    if isinstance(msg_or_class, str):
        return '/'.join(split_type_name(msg_or_class))
    cls = msg_or_class if isinstance(msg_or_class, type) else type(msg_or_class)
    module = getattr(cls, '__module__', '') or ''
    parts = module.split('.')
    # Generated classes live in modules like nav_msgs.msg._odometry and carry typesupport
    # hooks on their metaclass.
    if len(parts) < 2 or not hasattr(type(cls), '_TYPE_SUPPORT'):
        raise TypeError(f'{cls.__module__}.{cls.__qualname__} is not a ROS 2 message type')
    return f'{parts[0]}/{parts[1]}/{cls.__name__}'


@lru_cache(maxsize=None)
def message_class(type_name: str) -> type:
    """Import and return the rclpy class of a message type.

    :param type_name: ``pkg/msg/Type`` or ``pkg/Type``.
    :return: the generated Python class, for example ``nav_msgs.msg.Odometry``.
    :raises DefinitionNotFoundError: if the package or type is not installed.
    """
    package, namespace, name = split_type_name(type_name)
    try:
        module = importlib.import_module(f'{package}.{namespace}')
        return getattr(module, name)
    except (ImportError, AttributeError):
        raise DefinitionNotFoundError(
            f'message type {package}/{namespace}/{name} is not installed') from None


def _definition_path(type_name: str, extension: str) -> Path:
    package, namespace, name = split_type_name(type_name)
    try:
        share = Path(get_package_share_directory(package))
    except (PackageNotFoundError, ValueError):
        raise DefinitionNotFoundError(
            f'package {package!r} of {type_name} is not in the ament index') from None
    except OSError as exc:
        # ament_index_python's EnvironmentError: AMENT_PREFIX_PATH unset or empty.
        raise DefinitionNotFoundError(f'{type_name}: {exc}') from None
    path = share / namespace / f'{name}{extension}'
    if not path.is_file():
        raise DefinitionNotFoundError(f'no {path.name} in {path.parent}')
    return path


@lru_cache(maxsize=None)
def _load_spec(type_name: str, idl: bool) -> tuple[str, tuple[str, ...]]:
    """Read one definition file and the sorted names of the types it refers to."""
    path = _definition_path(type_name, '.idl' if idl else '.msg')
    # Bytes decoded without newline translation: rosbag2 copies the file verbatim.
    text = path.read_bytes().decode('utf-8')
    if idl:
        dependencies = set(_IDL_INCLUDE.findall(text))
    else:
        package = split_type_name(type_name)[0]
        dependencies = {
            field_type if '/' in field_type else f'{package}/{field_type}'
            for field_type in _MSG_FIELD_TYPE.findall(text)
            if field_type not in _PRIMITIVE_TYPES}
    # std::set<std::string> orders by bytes; Python's str order agrees for ASCII names.
    return text, tuple(sorted(dependencies))


def _delimiter(type_name: str, idl: bool) -> str:
    return f"{DELIMITER_LINE}\n{'IDL' if idl else 'MSG'}: {type_name}\n"


def _full_text(root: str, idl: bool) -> str:
    seen: set[str] = set()

    def append_recursive(type_name: str, depth: int) -> str:
        if depth <= 0:
            raise RecursionError(f'reached max recursion depth resolving definition of {root}')
        text, dependencies = _load_spec(type_name, idl)
        parts = [text]
        for dependency in dependencies:
            if dependency not in seen:
                seen.add(dependency)
                parts += ['\n', _delimiter(dependency, idl),
                          append_recursive(dependency, depth - 1)]
        return ''.join(parts)

    if idl:
        return _delimiter(root, idl) + append_recursive(root, MAX_RECURSION_DEPTH)
    return append_recursive(root, MAX_RECURSION_DEPTH)


@lru_cache(maxsize=None)
def encoded_definition(type_name: str) -> MessageDefinition:
    """Build the schema rosbag2 writes for a type: ``ros2msg``, else ``ros2idl``.

    :param type_name: ``pkg/msg/Type`` (or ``pkg/Type``).
    :return: the definition, named ``pkg/msg/Type`` as rosbag2 names its schemas.
    :raises DefinitionNotFoundError: if neither a ``.msg`` nor an ``.idl`` file is installed
        for the type or one of its dependencies.
    """
    full_name = type_name_of(type_name)
    try:
        return MessageDefinition(full_name, ENCODING_MSG, _full_text(full_name, idl=False))
    except DefinitionNotFoundError as msg_error:
        try:
            return MessageDefinition(full_name, ENCODING_IDL, _full_text(full_name, idl=True))
        except DefinitionNotFoundError:
            raise DefinitionNotFoundError(
                f'no message definition for {full_name}: {msg_error}') from None


def message_definition(type_name: str) -> str:
    """Return the ``ros2msg`` schema text of a type, as rosbag2 writes it.

    For example ``message_definition('nav_msgs/msg/Odometry')`` is the text of
    ``Odometry.msg`` followed by ``MSG: geometry_msgs/PoseWithCovariance``, its dependencies,
    and so on, each type once.

    :param type_name: ``pkg/msg/Type`` (or ``pkg/Type``).
    :return: the full definition text.
    :raises DefinitionNotFoundError: if a definition file is missing.
    """
    return encoded_definition(type_name).text


@lru_cache(maxsize=None)
def type_hash(type_name: str) -> str:
    """Return the type description hash (``RIHS01_...``) of a message type, or ``''``.

    rosidl installs it beside the ``.msg`` file (``<Type>.json``); it is the hash a publisher
    of the type advertises and that rosbag2 records as ``type_description_hash``.

    :param type_name: ``pkg/msg/Type`` (or ``pkg/Type``).
    :return: the hash string, or ``''`` when the ``.json`` file is not installed.
    """
    full_name = type_name_of(type_name)
    try:
        path = _definition_path(full_name, '.json')
        hashes = json.loads(path.read_text(encoding='utf-8'))['type_hashes']
    except (DefinitionNotFoundError, ValueError, KeyError, TypeError):
        return ''
    for entry in hashes:
        if isinstance(entry, dict) and entry.get('type_name') == full_name:
            return str(entry.get('hash_string', ''))
    return ''
