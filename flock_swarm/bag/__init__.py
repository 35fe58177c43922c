"""rosbag2-compatible MCAP bags: write them while recording, read them back (even truncated).

:class:`BagWriter` produces the directory layout of ``ros2 bag record -s mcap`` on Jazzy
(``metadata.yaml`` and ``<name>_0.mcap`` with ``ros2msg`` schemas and ``cdr`` channels);
:class:`BagReader` reads such bags, and recovers the complete chunks of an unfinished one.
"""

from flock_swarm.bag.msgdefs import (
    DefinitionNotFoundError, encoded_definition, message_class, message_definition,
    MessageDefinition, type_hash, type_name_of)
from flock_swarm.bag.reader import BagError, BagMessage, BagReader, parse_qos_profiles
from flock_swarm.bag.writer import BagWriter, serialize_qos_profiles

__all__ = [
    'BagError',
    'BagMessage',
    'BagReader',
    'BagWriter',
    'DefinitionNotFoundError',
    'encoded_definition',
    'message_class',
    'message_definition',
    'MessageDefinition',
    'parse_qos_profiles',
    'serialize_qos_profiles',
    'type_hash',
    'type_name_of',
]
