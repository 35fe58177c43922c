"""Low-level checks of scenario values: each raises :class:`ScenarioError` naming its key.

Shared by the scenario schema (:mod:`flock_swarm.core.scenario`), the laws and the leader
models, so a plugin validates its parameters with the same messages as the built-ins.
"""

import math
from typing import Any

import numpy as np

from flock_swarm.core.errors import ScenarioError

#: The largest float; a YAML integer beyond it cannot be converted (OverflowError).
_FLOAT_MAX = int(np.finfo(float).max)
#: The largest magnitude of any scenario number (positions in m, velocities in m/s, gains,
#: radii). Finite but huge values overflow float64 in the laws' squares and pair sums
#: (``||q_i - q_j||^2`` of 1e300 is inf) long before they mean anything physical; 1e12 keeps
#: squares, products and sums over a million agents far inside the float range.
MAX_MAGNITUDE = 1e12


def require(cond: bool, key: str, reason: str) -> None:
    """Raise ``ScenarioError(key, reason)`` unless ``cond`` holds.

    :param cond: the condition a valid value meets.
    :param key: the dotted scenario key, e.g. ``'protocol.c1'``.
    :param reason: what is wrong, e.g. ``'must be > 0, got -1'``.
    """
    if not cond:
        raise ScenarioError(key, reason)


def number(value: Any, key: str) -> float:
    """Return ``value`` as a finite float of sensible magnitude."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ScenarioError(key, f'expected a number, got {value!r}')
    if isinstance(value, int) and abs(value) > _FLOAT_MAX:
        raise ScenarioError(key, f'must be finite, got an integer of {value.bit_length()} bits '
                            '(beyond the float range)')
    if not math.isfinite(value):
        raise ScenarioError(key, f'must be finite, got {value!r}')
    if abs(value) > MAX_MAGNITUDE:
        raise ScenarioError(key, f'magnitude must be <= {MAX_MAGNITUDE:g}, got {value!r}')
    return float(value)


def integer(value: Any, key: str) -> int:
    """Return ``value`` as an int (a float with an integer value is accepted)."""
    if isinstance(value, bool) or not isinstance(value, int):
        if isinstance(value, float) and value.is_integer():
            return int(value)
        raise ScenarioError(key, f'expected an integer, got {value!r}')
    return int(value)


def positive(value: Any, key: str) -> float:
    """Return ``value`` as a float ``> 0``."""
    x = number(value, key)
    if x <= 0.0:
        raise ScenarioError(key, f'must be > 0, got {value!r}')
    return x


def vector(value: Any, key: str, length: int) -> np.ndarray:
    """Return ``value`` as a vector of ``length`` numbers."""
    if not isinstance(value, (list, tuple)):
        raise ScenarioError(key, f'expected a list of {length} numbers, got {value!r}')
    if len(value) != length:
        raise ScenarioError(key, f'expected {length} values (dim = {length}), got {len(value)}')
    return np.array([number(v, f'{key}[{k}]') for k, v in enumerate(value)])


def matrix(value: Any, key: str, rows: int, cols: int) -> np.ndarray:
    """Return ``value`` as a ``rows x cols`` matrix (a list of rows)."""
    if not isinstance(value, (list, tuple)) or len(value) != rows:
        raise ScenarioError(key, f'expected a {rows} x {cols} matrix (list of {rows} rows)')
    return np.array([vector(row, f'{key}[{k}]', cols) for k, row in enumerate(value)])


def text(value: Any, key: str, default: str) -> str:
    """Return ``value`` as text (numbers and booleans read as text), ``default`` if absent."""
    # Dates, binary and containers would not survive the scenario's JSON copies
    # (scenario.json, the bag's metadata).
    if value is None:
        return default
    if not isinstance(value, (str, int, float)) or (isinstance(value, float)
                                                    and not math.isfinite(value)):
        raise ScenarioError(key, f'expected text, got {value!r}'[:200])
    return str(value)


def mapping(value: Any, key: str) -> dict:
    """Return ``value`` as a mapping (``{}`` when absent)."""
    if value is None:
        return {}
    if not isinstance(value, dict):
        raise ScenarioError(key, f'expected a mapping, got {value!r}')
    return value


def only(section: dict, allowed, prefix: str) -> None:
    """Raise for the first key of ``section`` not in ``allowed``."""
    for name in section:
        if name not in allowed:
            raise ScenarioError(f'{prefix}{name}',
                                f'unknown key (expected one of: {", ".join(allowed)})')


def choice(value: Any, key: str, options) -> str:
    """Return ``value`` if it is one of ``options``."""
    # A list or mapping is not hashable: compare, never look up.
    if not isinstance(value, str) or value not in options:
        raise ScenarioError(key, f'unknown value {value!r} '
                            f'(expected one of: {", ".join(options)})')
    return value
