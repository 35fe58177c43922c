"""Building rclpy messages by hand, for tests that publish what a node would (or would not).

The nodes themselves write serialised bytes (:mod:`flock_swarm.nodes.wire`); these build
the typed messages, so a test's faulty or forged input is independent of that encoder.
"""

from typing import Sequence

from builtin_interfaces.msg import Time
from geometry_msgs.msg import AccelStamped
from nav_msgs.msg import Odometry

from flock_swarm.contract import FRAME


def make_odometry(q: Sequence[float], p: Sequence[float], stamp: Time, child: str,
                  msg: Odometry | None = None) -> Odometry:
    """Return an Odometry with position ``q`` and world-frame velocity ``p`` (2-D: z = 0).

    :param q: position (an array or a list of floats, length ``dim``).
    :param p: velocity.
    :param stamp: the header stamp.
    :param child: ``child_frame_id`` (used when a new message is built).
    :param msg: a message to fill in place (a node publishing every step reuses one per
        topic, since building a nested message costs more than sending it); ``None``: new.
    """
    if msg is None:
        msg = Odometry()
        msg.header.frame_id = FRAME
        msg.child_frame_id = child
    msg.header.stamp = stamp
    pos = msg.pose.pose.position
    vel = msg.twist.twist.linear
    pos.x, pos.y = float(q[0]), float(q[1])
    vel.x, vel.y = float(p[0]), float(p[1])
    if len(q) == 3:
        pos.z, vel.z = float(q[2]), float(p[2])
    return msg


def make_accel(a: Sequence[float], stamp: Time,
               msg: AccelStamped | None = None) -> AccelStamped:
    """Return an AccelStamped with linear acceleration ``a`` in the world frame.

    :param msg: a message to fill in place (see :func:`make_odometry`); ``None``: new.
    """
    if msg is None:
        msg = AccelStamped()
        msg.header.frame_id = FRAME
    msg.header.stamp = stamp
    lin = msg.accel.linear
    lin.x, lin.y = float(a[0]), float(a[1])
    if len(a) == 3:
        lin.z = float(a[2])
    return msg
