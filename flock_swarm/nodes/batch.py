"""The compiled message path: a lockstep step's serialised messages moved through rcl at once.

Through rclpy every message a step carries costs an executor event, a Python call to take
it and a callback (and every message sent a Python call to publish it): at N = 1000 that
per-message work, not the flocking, bounds the pipeline (docs/performance.md, issue 28).
The C extension :mod:`flock_swarm._rclbatch` (built by ``setup.py`` against the rcl headers
and libraries of the installed ROS wheels) takes every waiting message of a list of rcl
subscriptions into one buffer in one call, and publishes a list of serialised messages
from one buffer in one call. Nodes, executor, QoS, discovery and topics stay rclpy's and
the contract's; only the per-message loop leaves Python.

:class:`BatchTake` takes every waiting message of a step's subscriptions (the world's:
every agent's command; an agent host's: every agent's odometry) when the first of them
comes: the executor's events for the rest find nothing left and call nothing, so a step
costs one callback, not one a message. The node's inbox gets the same bytes as through
rclpy's callbacks and judges them the same way (checks, counts and rejections unchanged).
:class:`BatchPublish` publishes a step's messages.

Which path runs (:func:`use_c_path`): the node parameter ``message_path`` (``auto``, ``c``,
``rclpy``), else the environment variable :data:`ENV` (same values), else ``auto``: the
extension when it is built. The outputs are bit-identical either way (the tests run the
equivalence tests on both paths).
"""

import os
from typing import Any, Callable, Sequence

import numpy as np

from flock_swarm.core.errors import ScenarioError
from flock_swarm.nodes.parameters import Param

#: The environment variable choosing the message path when ``message_path`` is ``auto``.
ENV = 'FLOCK_SWARM_MESSAGE_PATH'
#: The message paths: the extension when built, the extension (an error if not built),
#: pure rclpy.
PATHS = ('auto', 'c', 'rclpy')
#: The nodes' parameter choosing the message path.
MESSAGE_PATH = Param('message_path', 'auto', "lockstep message path: 'c' (the compiled "
                     "extension flock_swarm._rclbatch), 'rclpy' (pure rclpy), 'auto' (the "
                     f"environment variable {ENV} if set, else c when built)",
                     lambda v: v in PATHS, "must be 'auto', 'c' or 'rclpy', got {value!r}")

_extension = None
_missing: str | None = None


def extension():
    """Return the module :mod:`flock_swarm._rclbatch`, or ``None`` when it is not built
    (:func:`why_not_built` says why)."""
    global _extension, _missing
    if _extension is None and _missing is None:
        try:
            from flock_swarm import _rclbatch
        except ImportError as exc:
            _missing = f'flock_swarm._rclbatch does not import: {exc}'
        else:
            _extension = _rclbatch
    return _extension


def why_not_built() -> str | None:
    """Return why the extension is not available, or ``None`` when it is."""
    extension()
    return _missing


def use_c_path(parameter: str = 'auto') -> bool:
    """Return whether the compiled message path runs.

    :param parameter: the node's ``message_path`` (``auto`` defers to :data:`ENV`).
    :raises ScenarioError: for an unknown value of :data:`ENV`, or ``c`` asked for and the
        extension not built.
    """
    choice, key = parameter, MESSAGE_PATH.name
    if choice == 'auto':
        env = os.environ.get(ENV, '')
        if env not in ('',) + PATHS:
            raise ScenarioError(ENV, f"must be 'auto', 'c' or 'rclpy', got {env!r}")
        choice, key = env or 'auto', ENV
    if choice == 'rclpy':
        return False
    if extension() is None:
        if choice == 'c':
            raise ScenarioError(key, f"'c' needs the C extension: {why_not_built()} (rebuild "
                                "the package; 'auto' falls back to rclpy)")
        return False
    return True


class _Held:
    """rclpy handles held in use while the extension's object holds their rcl pointers (so
    rclpy destroys none of them underneath it), released by :meth:`close`."""

    def __init__(self, entities: Sequence, make: Callable[[list[int]], Any]) -> None:
        """Enter every ``entity.handle`` and set :attr:`native` to ``make(pointers)``."""
        self.handles = [entity.handle for entity in entities]
        for handle in self.handles:
            handle.__enter__()
        self.native = make([handle.pointer for handle in self.handles])

    def close(self) -> None:
        """Free the extension's object and release the handles (idempotent)."""
        if self.native is None:
            return
        self.native.close()
        self.native = None
        for handle in self.handles:
            handle.__exit__(None, None, None)
        self.handles = []


def release(*held: '_Held | None') -> None:
    """Close each of ``held`` that is not ``None`` (a node's, before it is destroyed)."""
    for one in held:
        if one is not None:
            one.close()


class BatchTake(_Held):
    """Every waiting message of a set of rclpy subscriptions taken at once.

    The subscriptions stay the node's (the executor's events and callbacks are rclpy's):
    the node takes the rest of the step from the callback of the step's first message, and
    the executor's events for the messages taken so find nothing waiting and call nothing.
    """

    def __init__(self, subscriptions: Sequence) -> None:
        """Hold ``subscriptions`` (rclpy subscriptions, in use until :meth:`close`)."""
        super().__init__(subscriptions, extension().Taker)

    def take(self) -> list[tuple[int, bytes]]:
        """Return every waiting message as ``(subscription index, bytes)``, subscription by
        subscription (each one's in order of arrival)."""
        data, meta = self.native.take()
        if not meta:
            return []
        rows = np.frombuffer(meta, dtype=np.int64).reshape(-1, 3)
        ends = np.cumsum(rows[:, 1]).tolist()
        starts = [0] + ends[:-1]
        return [(i, data[lo:hi]) for i, lo, hi in zip(rows[:, 0].tolist(), starts, ends)]


class BatchPublish(_Held):
    """A step's serialised messages published at once on a list of rclpy publishers."""

    def __init__(self, publishers: Sequence) -> None:
        """Hold ``publishers`` (rclpy publishers, in use until :meth:`close`)."""
        super().__init__(publishers, extension().Publishers)

    def publish(self, messages: Sequence[tuple[int, bytes]]) -> None:
        """Publish each ``(publisher index, bytes)`` of ``messages``, in order."""
        if not messages:
            return
        targets = np.fromiter((row for row, _ in messages), dtype=np.int64, count=len(messages))
        self.publish_to(targets, [data for _, data in messages])

    def publish_to(self, targets: np.ndarray, messages: Sequence[bytes]) -> None:
        """Publish ``messages[m]`` on publisher ``targets[m]`` (int64), in order."""
        sizes = np.fromiter(map(len, messages), dtype=np.int64, count=len(messages))
        self.native.publish(b''.join(messages), targets, sizes)
