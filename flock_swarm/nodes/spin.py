"""Spinning a node: the executor every node and runner uses, and a node's ``main``.

:func:`run_node` runs one node as ros2/demos do (init, spin, clean shutdown) and turns
invalid configuration into one line on stderr with exit status 2.
"""

import os
import re
import signal
import sys
from typing import Callable

from rclpy.node import Node

from flock_swarm.console import (EXIT_FAILURE, EXIT_SIGNAL, EXIT_USAGE, FAIL_SIGNAL,
                                 STOP_SIGNALS, StopSignals)
from flock_swarm.core.errors import ScenarioError, one_line


#: rmw_fastrtps's publication mode, and the mode this package's processes use unless the
#: environment names one: ``SYNCHRONOUS`` writes each message in the publishing thread (no hand-off
#: to Fast DDS's asynchronous thread), rmw_fastrtps's own default from ROS 2 Kilted on; Jazzy's is
#: ``ASYNCHRONOUS``. A lockstep step publishes 2N small messages: the one-way cost of N
#: odometries fell from 31-33 to 17-18 CPU-us a message at N = 1000 (docs/performance.md).
PUBLICATION_MODE = ('RMW_FASTRTPS_PUBLICATION_MODE', 'SYNCHRONOUS')


def middleware_defaults(environ=None) -> None:
    """Give the middleware this package's defaults where the environment is silent; call it
    before ``rclpy.init`` (rmw_fastrtps reads the variables when a context creates its
    participant).

    :param environ: the environment to complete (default: this process's, ``os.environ``,
        which the middleware reads).
    """
    name, value = PUBLICATION_MODE
    (os.environ if environ is None else environ).setdefault(name, value)


#: The most events a node stopped by a signal takes to learn whether its run had ended by
#: itself (:func:`run_node`'s ``completed``).
SETTLE_EVENTS = 100


def make_executor(context=None):
    """Return the executor every node and runner spins: rclpy's ``EventsExecutor``.

    It delivers about twice the messages per second of ``SingleThreadedExecutor`` on the
    project's 2-core machines (docs/performance.md).
    """
    from rclpy.experimental import EventsExecutor
    return EventsExecutor(context=context)


def wall_timer(node: Node, period: float, callback: Callable[[], None]):
    """Return a timer of ``node`` on the steady clock: it fires every ``period`` wall seconds
    whatever ``use_sim_time`` says.

    The nodes' timers time waits, retries and realtime pacing in wall time; the simulation's
    time is in the stamps. On the node's ROS clock they would wait for ``/clock`` under
    ``use_sim_time:=true``: the world (which publishes it) never started, and the leader and
    the agents slowed from about 500 to 22 steps per second.

    :param node: the node.
    :param period: seconds of wall time between calls.
    :param callback: called on every tick.
    """
    from rclpy.clock import Clock, ClockType
    return node.create_timer(period, callback, clock=Clock(clock_type=ClockType.STEADY_TIME))


def run_node(name: str, factory: Callable[[], Node], args: list[str] | None = None,
             until: Callable[[Node], bool] | None = None,
             on_fail: Callable[[Node], None] | None = None,
             completed: Callable[[Node], bool] | None = None) -> int:
    """Run one node as in ros2/demos: init, spin, clean shutdown; return the exit status.

    Invalid configuration is reported as one line on stderr with exit status 2. The node
    spins on :func:`make_executor`'s executor. A stop signal (SIGINT, SIGTERM, SIGHUP: see
    :class:`~flock_swarm.console.StopSignals`) only ends the spin, at any moment (while the
    node is being built too): the context stays valid until the node is closed and
    destroyed, so no callback meets an invalid context (rclpy's own handlers shut it down
    under a running callback), and the exit status is the signal's
    (:data:`~flock_swarm.console.EXIT_SIGNAL`: 130, 143, 129), unless ``completed`` says
    the node's run had ended by itself: the messages it had received when the signal came
    are taken first (at most :data:`SETTLE_EVENTS`).

    Run as a process (``args`` is ``None``: the command line), the node ignores stop signals
    from the end of its run to the exit: ``ros2 launch`` sends SIGINT to the leader and the
    agents when the world exits, as they finish on their own, and one that came after the
    handlers were restored made a cleanly finished node die of it (exit code -2).

    :param name: executable name (prefix of error lines).
    :param factory: builds the node (after ``rclpy.init``).
    :param args: command-line arguments (``None``: ``sys.argv``, and this is the process's
        node: see above).
    :param until: optional condition ending the spin (the world ends after its last step).
    :param on_fail: when given, :data:`~flock_swarm.console.FAIL_SIGNAL` (a supervisor saw
        another process of the run die) ends the spin too: ``on_fail`` gets the node before
        it is closed, and the exit status is :data:`~flock_swarm.console.EXIT_FAILURE`.
    :param completed: whether the node's run has ended by itself (the leader and the agents:
        the world announced ``completed``); a stop signal then leaves the exit status 0.
    :return: the exit status.
    """
    failed: list[int] = []
    previous = None
    if on_fail is not None:
        previous = signal.signal(FAIL_SIGNAL, lambda number, frame: failed.append(number))
    stop = StopSignals().__enter__()
    try:
        status, stopped = _spin(name, factory, args, until,
                                lambda: bool(stop.received or failed),
                                lambda node: on_fail(node) if failed else None,
                                None if completed is None else
                                lambda node: not failed and completed(node))
    finally:
        if args is None:
            # The process's node: its handlers replaced at once, never restored (a signal
            # between the two would raise KeyboardInterrupt).
            ignore_stop_signals()
        else:
            stop.__exit__(None, None, None)
        if previous is not None:
            signal.signal(FAIL_SIGNAL, previous)
    # A signal that comes while the node closes after its run ended by itself changes nothing.
    if status != 0 or not stopped:
        return status
    return EXIT_SIGNAL[stop.first] if stop.received else EXIT_FAILURE


def ignore_stop_signals() -> None:
    """Ignore the stop signals (:data:`~flock_swarm.console.STOP_SIGNALS`) for the rest of
    the process: its run is over and its outputs are written, so a signal can only change
    its exit status (ignored, they stay ignored while the interpreter finalises)."""
    for sig in STOP_SIGNALS:
        signal.signal(sig, signal.SIG_IGN)


def _spin(name: str, factory: Callable[[], Node], args: list[str] | None,
          until: Callable[[Node], bool] | None, signalled: Callable[[], bool],
          before_close: Callable[[Node], None],
          completed: Callable[[Node], bool] | None = None) -> tuple[int, bool]:
    """:func:`run_node` with its signal handlers installed: return the exit status and
    whether a signal ended the spin (``signalled``: whether one came; ``before_close`` gets
    the node before it is closed; ``completed``: see :func:`run_node`)."""
    import rclpy
    from rclpy.impl.implementation_singleton import rclpy_implementation
    from rclpy.logging import LoggingSeverity, get_logger_level, set_logger_level
    from rclpy.signals import SignalHandlerOptions
    # rcl logs a line of its own for malformed arguments; the reason is in the error below.
    previous = get_logger_level('rcl')
    set_logger_level('rcl', LoggingSeverity.FATAL)
    try:
        middleware_defaults()
        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    except rclpy_implementation.RCLError as exc:
        set_logger_level('rcl', previous)
        reason = str(exc).removeprefix('failed to initialize rcl: ')
        if reason.startswith('ROS_DOMAIN_ID '):
            # rcl: "ROS_DOMAIN_ID is not an integral number, at .../domain_id.c:49".
            got = os.environ.get('ROS_DOMAIN_ID', '')
            print(f'{name}: error: ROS_DOMAIN_ID: must be a domain id in [0, 232], got '
                  f'{got!r}', file=sys.stderr)
            return EXIT_USAGE, False
        if "Couldn't parse" not in reason:
            raise
        # A malformed --ros-args rule ('-p key' without ':=', unparsable YAML, a missing
        # params file): rcl's message, without the C source locations it appends.
        reason = re.split(r'(?:\. Error: |, at /)', reason, maxsplit=1)[0]
        print(f'{name}: error: --ros-args: {one_line(reason)}', file=sys.stderr)
        return EXIT_USAGE, False
    if get_logger_level('rcl') == LoggingSeverity.FATAL:
        # Unless --ros-args --log-level set the rcl logger's level itself.
        set_logger_level('rcl', previous)
    node = None
    executor = None
    status = 0
    stopped = False
    try:
        node = factory()
        executor = make_executor()
        executor.add_node(node)
        while not (stopped := signalled()) and rclpy.ok() and (until is None or not until(node)):
            executor.spin_once(timeout_sec=0.1)
        if stopped and completed is not None:
            # ros2 launch signals the leader and the agents when the world exits: its
            # announcement of the end came before, perhaps not yet taken.
            for _ in range(SETTLE_EVENTS):
                if completed(node):
                    break
                executor.spin_once(timeout_sec=0.0)
            stopped = not completed(node)
    except ScenarioError as exc:
        print(f'{name}: error: {exc}', file=sys.stderr)
        status = EXIT_USAGE
    finally:
        if node is not None:
            before_close(node)
            close = getattr(node, 'close', None)
            if close is not None:
                close()
        if executor is not None:
            executor.shutdown()
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return status, stopped
