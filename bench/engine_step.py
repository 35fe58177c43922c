"""The MuJoCo Burger's step response under cmd_vel: rise time, overshoot, settling.

    python bench/engine_step.py [--seconds 1.0]

One TurtleBot3 Burger of flock_swarm/engine/turtlebot3_burger.xml on the floor, driven by
:class:`~flock_swarm.engine.mujoco_world.EngineWorld` (the world's backend and
``engine_robots`` drive it the same way): it holds a twist until it is steady, then the
command steps, and the robot's forward speed (or yaw rate) is read at every 2 ms engine step
twice: as the engine's odometry gives it (the base's velocity, ``EngineWorld.velocities``,
which the robot's pitching moves) and as wheel encoders would (the wheels' mean speed times
the radius, or their difference over the separation). Printed per step and reading: the
10-90 % rise time, the peak and its overshoot in % of the step, the time to stay within 2 % of
the step around the final value, that final value, and the largest pitch of the chassis.
"""

import argparse

import mujoco
import numpy as np

from flock_swarm.engine.mujoco_world import TURTLEBOT3_BURGER, EngineWorld

#: The steps (name, from (v, omega), to (v, omega), the component read: 0 speed, 1 yaw rate).
STEPS = (
    ('speed 0 -> 0.22 m/s', (0.0, 0.0), (0.22, 0.0), 0),
    ('speed 0 -> 0.10 m/s', (0.0, 0.0), (0.10, 0.0), 0),
    ('speed 0.22 -> -0.22 m/s', (0.22, 0.0), (-0.22, 0.0), 0),
    ('speed 0.10 -> 0.12 m/s', (0.10, 0.0), (0.12, 0.0), 0),
    ('yaw rate 0 -> 2.84 rad/s', (0.0, 0.0), (0.0, 2.84), 1),
    ('yaw rate 0 -> 1.0 rad/s', (0.0, 0.0), (0.0, 1.0), 1),
)


def response(start: tuple, end: tuple, component: int, seconds: float
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Return the times, the readings after the step (base and wheels, ``(n, 2)``), the
    chassis' pitch [deg] and the readings before it."""
    world = EngineWorld(np.zeros((1, 2)), np.zeros(1))
    step = world.model.opt.timestep
    m, d, kin = world.model, world.data, TURTLEBOT3_BURGER
    wheels = [m.jnt_dofadr[m.actuator_trnid[a, 0]] for a in world._actuators[0]]
    root = world._qpos[0]

    def read() -> tuple[float, float]:
        vx, vy, wz = world.velocities()[0]
        yaw = world.poses()[0, 2]
        left, right = d.qvel[wheels] * kin.wheel_radius
        if component == 0:
            return float(np.cos(yaw) * vx + np.sin(yaw) * vy), float(0.5 * (left + right))
        return float(wz), float((right - left) / kin.wheel_separation)

    def pitch() -> float:
        rot = np.zeros(9)
        mujoco.mju_quat2Mat(rot, d.qpos[root + 3:root + 7])
        return float(np.degrees(np.arcsin(np.clip(-rot[6], -1.0, 1.0))))
    world.set_twists(np.array([start[0]]), np.array([start[1]]))
    for _ in range(int(round(2.0 / step))):
        world.step(step)
    before = read()
    world.set_twists(np.array([end[0]]), np.array([end[1]]))
    t, y, tilt = [], [], []
    for k in range(int(round(seconds / step))):
        world.step(step)
        t.append((k + 1) * step)
        y.append(read())
        tilt.append(pitch())
    return np.array(t), np.array(y), np.array(tilt), before


def characterise(t: np.ndarray, y: np.ndarray, before: float, target: float) -> dict:
    """Return rise time, peak, overshoot, settling time and final value of one response."""
    size = target - before
    frac = (y - before) / size
    rise = t[np.argmax(frac >= 0.9)] - t[np.argmax(frac >= 0.1)]
    k = int(np.argmax(frac))
    final = float(y[-1])
    outside = np.flatnonzero(np.abs(y - final) > 0.02 * abs(size))
    settle = float(t[outside[-1] + 1]) if outside.size and outside[-1] + 1 < len(t) else 0.0
    return {'rise_ms': 1e3 * float(rise), 'peak': float(y[k]),
            'overshoot_pct': 100.0 * max(0.0, float(frac[k]) - 1.0),
            'settle_ms': 1e3 * settle, 'final': final}


def main() -> int:
    """Print one line per step."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--seconds', type=float, default=1.0)
    args = parser.parse_args()
    for name, start, end, component in STEPS:
        t, y, tilt, before = response(start, end, component, args.seconds)
        for col, reading in enumerate(('base', 'wheels')):
            f = characterise(t, y[:, col], before[col], end[component])
            print(f'{name:25s} {reading:6s} rise (10-90 %) {f["rise_ms"]:5.1f} ms  peak '
                  f'{f["peak"]:+.3f}  overshoot {f["overshoot_pct"]:5.1f} %  settled (2 %) '
                  f'{f["settle_ms"]:5.1f} ms  final {f["final"]:+.4f}'
                  + (f'  pitch up to {np.abs(tilt).max():.1f} deg' if col else ''))
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
