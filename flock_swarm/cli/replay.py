"""``replay BAG``: republish a recorded bag with its recorded timing, like ``ros2 bag play``.

Usage::

    replay BAG [--rate R] [--loop] [--topics T [T ...]] [--regex PATTERN]
               [--exclude PATTERN] [--start-offset S] [--clock] [--clock-rate HZ]
               [--wait-for-subscribers N] [--wait-timeout S] [--delay S] [--quiet]
               [--republish {as_recorded,per_agent}] [--foxglove [PORT]]
               [--foxglove-host HOST] [--ros-args ...]

A thin command over the player node (:class:`flock_swarm.nodes.player.Player`). Unless
``--quiet``, a progress line on stderr gives the bag time and the time elapsed since the start
of the bag; with ``--foxglove`` the replayed messages are also served over the Foxglove
WebSocket protocol (:mod:`flock_swarm.foxglove_ws`).

Invalid input (a missing path, a file that is not a bag, ``--rate 0``, a bad regular
expression, a topic the bag does not have; with ``--clock``, a domain held by a run of this
machine or one where another node publishes ``/clock``, a world started by hand say) prints
one line ``replay: error: ...`` and exits with status 2. Ctrl-C (or SIGTERM, SIGHUP) stops
the playback and exits with the signal's status (130, 143, 129:
:data:`~flock_swarm.console.EXIT_SIGNAL`). See ``docs/replay.md``.
"""

import argparse
import os
from pathlib import Path
import sys

from flock_swarm.bag import BagError
from flock_swarm.console import (claim_domain, DomainBusy, EXIT_FAILURE, EXIT_USAGE,
                                 OneLineParser, StopSignals)
from flock_swarm.foxglove_ws import DEFAULT_HOST, DEFAULT_PORT, ServeError, start_live
from flock_swarm.nodes.player import ClockTaken, Player, REPUBLISH, ReplayError
from flock_swarm.nodes.spin import middleware_defaults


def _count(number: int, noun: str, plural: str | None = None) -> str:
    return f'{number} {noun if number == 1 else plural or noun + "s"}'


def build_parser() -> argparse.ArgumentParser:
    """Return the command-line parser of ``replay``."""
    parser = OneLineParser(
        prog='replay', description='Republish the topics of a ROS 2 MCAP bag with their '
        'recorded timing and QoS, like ros2 bag play. Progress on stderr: [RUNNING]  Bag Time '
        'T  Duration ELAPSED/TOTAL (seconds).',
        epilog='ROS arguments go after --ros-args (remapping, namespace); the domain comes '
        'from ROS_DOMAIN_ID.')
    parser.add_argument('bag', type=Path, help='bag directory or .mcap file')
    parser.add_argument('-r', '--rate', type=float, default=1.0,
                        help='time scaling: 2 plays twice as fast (default 1)')
    parser.add_argument('-l', '--loop', action='store_true',
                        help='play again from the start offset after the end, until Ctrl-C')
    parser.add_argument('--topics', nargs='+', metavar='TOPIC',
                        help='replay only these topics (each must be in the bag)')
    parser.add_argument('-e', '--regex', metavar='PATTERN',
                        help='replay only topics matching this Python regular expression '
                        '(searched anywhere in the name)')
    parser.add_argument('-x', '--exclude', metavar='PATTERN',
                        help='do not replay topics matching this regular expression')
    parser.add_argument('--start-offset', type=float, default=0.0, metavar='S',
                        help='start S seconds after the first message of the bag')
    parser.add_argument('--clock', action='store_true',
                        help='publish /clock from bag time (a recorded /clock is then not '
                        'replayed)')
    parser.add_argument('--clock-rate', type=float, default=100.0, metavar='HZ',
                        help='/clock publications per second with --clock (default 100)')
    parser.add_argument('--wait-for-subscribers', type=int, default=0, metavar='N',
                        help='before playing, wait until a replayed topic has N subscribers '
                        '(then for discovery to settle, as always)')
    parser.add_argument('--wait-timeout', type=float, default=10.0, metavar='S',
                        help='longest wait for those subscribers and for discovery to '
                        'settle, then play anyway (default 10; 0: at once)')
    parser.add_argument('-d', '--delay', type=float, default=0.0, metavar='S',
                        help='wait S seconds before the first message (time for discovery)')
    parser.add_argument('-q', '--quiet', action='store_true',
                        help='no progress line and no summary')
    parser.add_argument('--republish', choices=REPUBLISH, default=REPUBLISH[0],
                        help='per_agent: a batched bag\'s /swarm/states and /swarm/commands '
                        'clouds as the per-agent topics agent_<i>/odom, agent_<i>/cmd_accel '
                        '(and /state, /cmd_vel), as a per-agent run records them (default '
                        'as_recorded)')
    parser.add_argument('--foxglove', type=int, nargs='?', const=DEFAULT_PORT, metavar='PORT',
                        help='also serve the replayed messages to Foxglove / Lichtblick over '
                        f'the Foxglove WebSocket protocol (default port {DEFAULT_PORT}; 0: '
                        'any free port)')
    parser.add_argument('--foxglove-host', default=DEFAULT_HOST, metavar='HOST',
                        help=f'address the --foxglove server binds (default {DEFAULT_HOST}: '
                        'this machine only)')
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run ``replay`` from the command line; return the exit status."""
    from rclpy.utilities import remove_ros_args

    if argv is None:
        argv = sys.argv[1:]
    try:
        own_args = remove_ros_args(['replay', *argv])[1:]
    except Exception as exc:
        # rclpy's parse errors (RCLInvalidROSArgsError, UnknownROSArgsError) have no common
        # base class but Exception.
        print(f"replay: error: --ros-args: {' '.join(str(exc).split())}", file=sys.stderr)
        return EXIT_USAGE
    args = build_parser().parse_args(own_args)
    try:
        _check_bounds(args)
        # A replay --clock drives a world's clock: held like a swarm's domain, so that it
        # is refused beside a running swarm and a swarm is refused beside it. A world
        # started by hand holds no lock: the player looks for its /clock on the graph.
        domain = _environment_domain()
        held = claim_domain(domain, 'replay --clock') if args.clock else None
    except (ReplayError, DomainBusy) as exc:
        key = 'ROS_DOMAIN_ID: ' if isinstance(exc, DomainBusy) else ''
        print(f'replay: error: {key}{exc}', file=sys.stderr)
        return EXIT_USAGE
    # The stop signals raise KeyboardInterrupt, as Ctrl-C does: the playback ends cleanly
    # (rclpy's own handlers, which shut the context down under a publish, are not installed).
    try:
        with StopSignals(interrupt=True) as stop:
            return stop.status(_play(args, argv))
    finally:
        if held is not None:
            held.close()


#: Bounds of the timing options beyond which a replay would never play (a rate of 1e-300
#: plays a bag second in 1e300 s) or overflow the bag's nanosecond time axis.
MIN_RATE = 1e-3
MAX_WAIT = 3600.0
MAX_START_OFFSET = 9e9


def _check_bounds(args: argparse.Namespace) -> None:
    """Refuse timing options a replay could not honour (one line naming the option).

    :raises ReplayError: for a rate below :data:`MIN_RATE`, a delay or wait timeout above
        :data:`MAX_WAIT` seconds, a start offset above :data:`MAX_START_OFFSET` seconds.
    """
    if args.rate > 0 and not args.rate >= MIN_RATE:
        raise ReplayError('--rate', f'must be >= {MIN_RATE:g} (a bag second would last more '
                          f'than {1 / MIN_RATE:g} s), got {args.rate:g}')
    for option, value in (('--delay', args.delay), ('--wait-timeout', args.wait_timeout)):
        if value > MAX_WAIT:
            raise ReplayError(option, f'must be at most {MAX_WAIT:g} s, got {value:g}')
    if args.start_offset > MAX_START_OFFSET:
        raise ReplayError('--start-offset', f'must be at most {MAX_START_OFFSET:g} s (the '
                          f'nanoseconds of a bag\'s time axis), got {args.start_offset:g}')


def _environment_domain() -> int:
    """Return the domain of ``$ROS_DOMAIN_ID`` (0 when unset or empty).

    :raises ReplayError: when it is not a whole number.
    """
    text = os.environ.get('ROS_DOMAIN_ID', '').strip()
    if not text.isdigit() and text:
        raise ReplayError('ROS_DOMAIN_ID', f'must be a domain id in [0, 232], got {text!r}')
    return int(text or 0)


def _play(args: argparse.Namespace, argv: list[str]) -> int:
    """Play the bag as ``args`` say (``argv``: the ROS arguments); return the exit status."""
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    player = None
    live = None
    try:
        if args.foxglove is not None:
            live = start_live(args.foxglove_host, args.foxglove, '--foxglove')
        middleware_defaults()
        rclpy.init(args=['replay', *argv], signal_handler_options=SignalHandlerOptions.NO)
        player = Player(
            args.bag, rate=args.rate, loop=args.loop, topics=args.topics, regex=args.regex,
            exclude=args.exclude, start_offset=args.start_offset, clock=args.clock,
            clock_rate=args.clock_rate, wait_subscribers=args.wait_for_subscribers,
            wait_timeout=args.wait_timeout, delay=args.delay,
            progress=None if args.quiet else sys.stderr, live=live, republish=args.republish)
        if live is not None and not args.quiet:
            print(f'[replay] live view on {live.url} ({len(live.channels)} topics)',
                  file=sys.stderr, flush=True)
        result = player.play()
    except ServeError as exc:
        print(f'replay: error: {exc}', file=sys.stderr)
        return EXIT_USAGE
    except (BagError, ReplayError) as exc:
        # Another /clock on the domain is invalid input, found once the player looked.
        status = EXIT_USAGE if player is None or isinstance(exc, ClockTaken) else EXIT_FAILURE
        print(f'replay: error: {exc}', file=sys.stderr)
        return status
    except KeyboardInterrupt:
        # A stop signal before the playback began (the player catches it while it plays).
        return 0
    finally:
        if player is not None:
            player.destroy_node()
        if live is not None:
            live.close()
        rclpy.try_shutdown()
    if not args.quiet:
        how = 'stopped' if result.interrupted else 'done'
        clock = f', {result.clock_ticks} /clock' if args.clock else ''
        print(f'[replay] {how}: {_count(result.total, "message")} on '
              f'{_count(len(result.published), "topic")}{clock} in '
              f'{_count(result.passes, "pass", "passes")}', file=sys.stderr, flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
