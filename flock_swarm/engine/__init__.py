"""What integrates the world: its backends, and a physics engine as one of them.

ROS-free: :mod:`flock_swarm.engine.backends` (the world's backends behind one interface,
chosen by name: the double integrator, the plant model, MuJoCo), and N differential-drive
robots in MuJoCo driven by ``cmd_vel`` (the world node's ``backend: mujoco`` and the
bridge's tests run it): see :mod:`flock_swarm.engine.mujoco_world` and docs/robots.md.
"""

# The world's backends (the world's ``backend`` parameter) and the one place choosing one:
# flock_swarm.engine.backends.
from flock_swarm.engine.backends import BACKENDS  # noqa: F401 (re-exported)
