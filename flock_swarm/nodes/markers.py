"""RViz / Foxglove markers and diagnostic metrics of the swarm.

:func:`swarm_markers` builds the markers as rclpy messages; :func:`swarm_markers_cdr`
writes the same message serialised (tested equal), at a fraction of the cost, and is what
the world publishes, with the metrics, through :class:`Telemetry`. The obstacles of a
scenario (:func:`obstacle_shapes`) are drawn in both, and alone, once and latched, on
``/swarm/obstacles`` (:func:`obstacle_markers`).
"""

import json

import numpy as np
from builtin_interfaces.msg import Duration, Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Point
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

from flock_swarm.core.graphs import EdgeList
from flock_swarm.core.headline import Headline, lead_with
from flock_swarm.core.obstacles import ObstacleSpec
from flock_swarm.bag.writer import serialize
from flock_swarm.contract import (DIAGNOSTICS, FRAME, MARKERS, METRICS, TELEMETRY_QOS,
                                  qos_profile)
from flock_swarm.nodes.wire import CdrWriter

UNINFORMED = ColorRGBA(r=0.2, g=0.45, b=0.9, a=1.0)
INFORMED = ColorRGBA(r=0.95, g=0.3, b=0.2, a=1.0)
LEADER = ColorRGBA(r=0.1, g=0.1, b=0.1, a=1.0)
#: Diagnostic levels (DiagnosticStatus.OK / WARN as integers).
OK, WARN = 0, 1
EDGE = ColorRGBA(r=0.5, g=0.5, b=0.5, a=0.6)
VELOCITY = ColorRGBA(r=0.1, g=0.7, b=0.3, a=0.9)
OBSTACLE = ColorRGBA(r=0.55, g=0.45, b=0.35, a=0.6)
#: The namespace of the obstacles' markers (one marker per obstacle, id = its index in the
#: map: spheres, then walls).
OBSTACLES_NS = 'obstacles'
#: How a wall (a half-space) is drawn: a slab this thick [m] behind its surface, this long
#: [m] along it (the viewers draw no infinite planes).
WALL_THICKNESS = 0.2
WALL_EXTENT = 500.0
#: The height [m] of the flat cylinder that draws a 2-D sphere (a disc) in the plane z = 0.
DISC_HEIGHT = 0.05


def _point(x: np.ndarray) -> Point:
    return Point(x=float(x[0]), y=float(x[1]), z=float(x[2]) if x.shape[0] == 3 else 0.0)


def _marker(mid: int, ns: str, kind: int, stamp: Time, frame: str, scale: float,
            color: ColorRGBA) -> Marker:
    m = Marker()
    m.header.stamp = stamp
    m.header.frame_id = frame
    m.ns = ns
    m.id = mid
    m.type = kind
    m.action = Marker.ADD
    m.pose.orientation.w = 1.0
    m.scale.x = m.scale.y = m.scale.z = scale
    m.color = color
    m.lifetime = Duration(sec=0, nanosec=0)
    return m


def _quaternion_x_to(a: np.ndarray) -> tuple[float, float, float, float]:
    """Return the unit quaternion ``(x, y, z, w)`` of the shortest rotation of x onto ``a``."""
    ax, ay, az = (float(v) for v in a)
    w = 1.0 + ax
    if w < 1e-12:
        return 0.0, 0.0, 1.0, 0.0  # a = -x: half a turn about z
    # The axis is x cross a = (0, -a_z, a_y); with w = 1 + cos, the half angle comes out.
    norm = np.sqrt(w * w + ay * ay + az * az)
    return 0.0, -az / norm, ay / norm, w / norm


def obstacle_shapes(spec: ObstacleSpec, dim: int) -> list[tuple]:
    """Return how each obstacle is drawn: ``(kind, position, orientation, scale)``.

    A sphere is a ``SPHERE`` (3-D) or a flat ``CYLINDER`` in the plane (2-D, a disc); a wall
    a ``CUBE``, a slab :data:`WALL_THICKNESS` thick behind its surface, :data:`WALL_EXTENT`
    long. Positions in 3-D (2-D: ``z = 0``); orientations ``(x, y, z, w)``.

    :param spec: the obstacles.
    :param dim: the scenario's dimension.
    :return: one tuple per obstacle, spheres then walls.
    """
    out = []
    for centre, radius in spec.spheres:
        pos = _points(np.array([centre]))[0]
        scale = (2 * radius,) * 3 if dim == 3 else (2 * radius, 2 * radius, DISC_HEIGHT)
        out.append((Marker.SPHERE if dim == 3 else Marker.CYLINDER, pos,
                    (0.0, 0.0, 0.0, 1.0), scale))
    for point, normal in spec.walls:
        a = _points(np.array([normal]))[0]
        pos = _points(np.array([point]))[0] - 0.5 * WALL_THICKNESS * a
        height = WALL_EXTENT if dim == 3 else DISC_HEIGHT
        out.append((Marker.CUBE, pos, _quaternion_x_to(a),
                    (WALL_THICKNESS, WALL_EXTENT, height)))
    return out


def _obstacle_marker(k: int, shape: tuple, stamp: Time, frame: str) -> Marker:
    kind, pos, orientation, scale = shape
    m = _marker(k, OBSTACLES_NS, kind, stamp, frame, 1.0, OBSTACLE)
    m.pose.position = Point(x=float(pos[0]), y=float(pos[1]), z=float(pos[2]))
    (m.pose.orientation.x, m.pose.orientation.y, m.pose.orientation.z,
     m.pose.orientation.w) = orientation
    m.scale.x, m.scale.y, m.scale.z = (float(v) for v in scale)
    return m


def obstacle_markers(spec: ObstacleSpec, dim: int, stamp: Time, frame: str) -> MarkerArray:
    """Return the obstacles alone (``/swarm/obstacles``, latched; :func:`obstacle_shapes`)."""
    out = MarkerArray()
    out.markers = [_obstacle_marker(k, shape, stamp, frame)
                   for k, shape in enumerate(obstacle_shapes(spec, dim))]
    return out


def swarm_markers(q: np.ndarray, p: np.ndarray, leader_q: np.ndarray, informed: np.ndarray,
                  edges: EdgeList, stamp: Time, frame: str, size: float,
                  obstacles: ObstacleSpec | None = None) -> MarkerArray:
    """Return agents (sphere list, informed highlighted), velocities, edges and the leader.

    :param q: positions ``(n, dim)``.
    :param p: velocities ``(n, dim)``.
    :param leader_q: the leader's position.
    :param informed: informed flags ``(n,)``.
    :param edges: the neighbour graph to draw.
    :param stamp: the simulation-time stamp.
    :param frame: the fixed frame.
    :param size: agent diameter [m].
    :param obstacles: the scenario's obstacles, drawn after the swarm (``None``: none).
    :return: the marker array.
    """
    agents = _marker(0, 'agents', Marker.SPHERE_LIST, stamp, frame, size, UNINFORMED)
    agents.points = [_point(x) for x in q]
    agents.colors = [INFORMED if f else UNINFORMED for f in informed]
    vel = _marker(1, 'velocities', Marker.LINE_LIST, stamp, frame, 0.2 * size, VELOCITY)
    vel.points = [pt for x, v in zip(q, p) for pt in (_point(x), _point(x + v))]
    links = _marker(2, 'neighbours', Marker.LINE_LIST, stamp, frame, 0.1 * size, EDGE)
    links.points = [pt for a, b in zip(edges.i, edges.j) for pt in (_point(q[a]), _point(q[b]))]
    lead = _marker(3, 'leader', Marker.SPHERE, stamp, frame, 2.0 * size, LEADER)
    lead.pose.position = _point(leader_q)
    out = MarkerArray()
    out.markers = [agents, vel, links, lead]
    if obstacles is not None and obstacles.active:
        out.markers += obstacle_markers(obstacles, q.shape[1], stamp, frame).markers
    return out


def _rgba(color: ColorRGBA) -> np.ndarray:
    return np.array([color.r, color.g, color.b, color.a], dtype='<f4')


def _points(x: np.ndarray) -> np.ndarray:
    """Return positions as ``geometry_msgs/Point`` rows (2-D: z = 0), little-endian."""
    out = np.zeros((x.shape[0], 3), dtype='<f8')
    out[:, :x.shape[1]] = x
    return out


def _write_marker(w: CdrWriter, mid: int, ns: str, kind: int, stamp_ns: int, frame: str,
                  scale: float | tuple, color: ColorRGBA, points: np.ndarray | None = None,
                  colors: np.ndarray | None = None, position: np.ndarray | None = None,
                  orientation: tuple = (0.0, 0.0, 0.0, 1.0)) -> None:
    """Write one ``visualization_msgs/Marker`` as :func:`_marker` builds it (Jazzy layout)."""
    w.time(stamp_ns)
    w.string(frame)
    w.string(ns)
    w.pack('iii', mid, kind, Marker.ADD, size=4)
    pos = (0.0, 0.0, 0.0) if position is None else tuple(_points(position[None])[0])
    w.pack('7d', *pos, *orientation, size=8)                        # pose
    scales = tuple(scale) if isinstance(scale, tuple) else (scale,) * 3
    w.pack('3d', *scales, size=8)                                   # scale
    w.pack('4f', *_rgba(color).tolist(), size=4)                    # color
    w.pack('iI?', 0, 0, False, size=4)                              # lifetime, frame_locked
    w.sequence(np.zeros((0, 3)) if points is None else points, 8)   # points
    w.sequence(np.zeros((0, 4), dtype='<f4') if colors is None else colors, 4)
    w.string('')                                                    # texture_resource
    w.time(0)                                                       # texture: header
    w.string('')
    w.string('')                                                    # format
    w.pack('I', 0, size=4)                                          # data
    w.pack('I', 0, size=4)                                          # uv_coordinates
    w.string('')                                                    # text
    w.string('')                                                    # mesh_resource
    w.string('')                                                    # mesh_file: filename
    w.pack('I', 0, size=4)                                          # data
    w.pack('?', False, size=1)                                      # embedded materials


def swarm_markers_cdr(q: np.ndarray, p: np.ndarray, leader_q: np.ndarray,
                      informed: np.ndarray, edges: EdgeList, stamp_ns: int, frame: str,
                      size: float, obstacles: ObstacleSpec | None = None) -> bytes:
    """Return :func:`swarm_markers`'s message serialised (``stamp_ns``: its stamp [ns])."""
    shapes = obstacle_shapes(obstacles, q.shape[1]) \
        if obstacles is not None and obstacles.active else []
    w = CdrWriter()
    w.pack('I', 4 + len(shapes), size=4)
    colors = np.where(np.asarray(informed, dtype=bool)[:, None], _rgba(INFORMED)[None],
                      _rgba(UNINFORMED)[None]).astype('<f4')
    _write_marker(w, 0, 'agents', Marker.SPHERE_LIST, stamp_ns, frame, size, UNINFORMED,
                  _points(q), colors)
    vel = np.stack([_points(q), _points(q + p)], axis=1).reshape(-1, 3)
    _write_marker(w, 1, 'velocities', Marker.LINE_LIST, stamp_ns, frame, 0.2 * size, VELOCITY,
                  vel)
    links = np.stack([_points(q[edges.i]), _points(q[edges.j])], axis=1).reshape(-1, 3)
    _write_marker(w, 2, 'neighbours', Marker.LINE_LIST, stamp_ns, frame, 0.1 * size, EDGE,
                  links)
    _write_marker(w, 3, 'leader', Marker.SPHERE, stamp_ns, frame, 2.0 * size, LEADER,
                  position=np.asarray(leader_q, dtype=float))
    for k, (kind, pos, orientation, scale) in enumerate(shapes):
        _write_marker(w, k, OBSTACLES_NS, kind, stamp_ns, frame, tuple(float(v) for v in scale),
                      OBSTACLE, position=pos, orientation=orientation)
    return w.getvalue()


def metrics_message(values: dict[str, float | int | str], stamp: Time, level: int = 0,
                    message: str = '') -> DiagnosticArray:
    """Return the live metrics as a DiagnosticArray with one status ``flock_swarm/metrics``.

    :param values: metric name to value.
    :param stamp: the simulation-time stamp.
    :param level: :class:`DiagnosticStatus` level (``WARN`` when commands were missed).
    :param message: a short human-readable summary.
    :return: the message.
    """
    status = DiagnosticStatus(level=bytes([level]), name='flock_swarm/metrics',
                              message=message, hardware_id='flock_swarm')
    status.values = [KeyValue(key=k, value=repr(v) if isinstance(v, float) else str(v))
                     for k, v in values.items()]
    out = DiagnosticArray()
    out.header.stamp = stamp
    out.status = [status]
    return out


class Telemetry:
    """The markers and ``/swarm/metrics`` of the steps the world observes, published and
    recorded (the world is a :class:`~flock_swarm.nodes.recording.RecordedNode`)."""

    def __init__(self, node, radius: float, informed: np.ndarray,
                 headline: Headline = Headline(),
                 obstacles: ObstacleSpec | None = None) -> None:
        """Create the two publishers on ``node``.

        :param node: the world node (its ``clock`` stamps the messages).
        :param radius: the interaction radius (the markers' scale).
        :param informed: which agents are informed (their colour).
        :param headline: the scenario's headline: the metrics' first values (a viewer's
            diagnostics panel lists them first).
        :param obstacles: the scenario's obstacles, drawn with the swarm.
        """
        self.node, self.radius, self.informed = node, radius, informed
        self.headline, self.obstacles = headline, obstacles
        qos = qos_profile(TELEMETRY_QOS)
        self.marker_pub = node.recorded_publisher(MarkerArray, MARKERS, qos)
        self.metrics_pub = node.recorded_publisher(DiagnosticArray, METRICS, qos)
        #: The same messages on /diagnostics, for ROS's diagnostics tools (not recorded).
        self.diagnostics_pub = node.create_publisher(DiagnosticArray, DIAGNOSTICS, qos)

    def emit(self, obs, rejected: dict) -> None:
        """Publish the markers and metrics due for an observed step.

        :param obs: the :class:`~flock_swarm.nodes.stepper.Observation`.
        :param rejected: the messages rejected so far, by reason (a metrics value).
        """
        node, clock = self.node, self.node.clock
        t_ns = clock.ns(obs.k)
        if obs.markers:
            node.publish_recorded(self.marker_pub, swarm_markers_cdr(
                obs.q, obs.p, obs.leader.q, self.informed, obs.edges, t_ns, FRAME,
                0.1 * self.radius, self.obstacles), t_ns)
        if obs.metrics is not None:
            values = lead_with(dict(obs.metrics, rejected_messages=json.dumps(rejected)),
                               self.headline)
            data = serialize(metrics_message(values, clock.stamp(obs.k),
                                             WARN if obs.problems else OK,
                                             ', '.join(obs.problems) or 'ok'))
            node.publish_recorded(self.metrics_pub, data, t_ns)
            self.diagnostics_pub.publish(data)
