"""A physics engine as the world: N differential-drive robots in MuJoCo, driven by ``cmd_vel``.

ROS-free (the world node's ``backend: mujoco`` and the bridge's tests run it): see
:mod:`flock_swarm.engine.mujoco_world` and docs/robots.md.
"""

#: The world's backends (the world's ``backend`` parameter): the plant model's own
#: integration, or the physics engine (:mod:`flock_swarm.engine.backend`).
BACKENDS = ('plant', 'mujoco')
