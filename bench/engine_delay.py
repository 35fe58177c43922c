"""What odometry delay does to the robots' velocity loop: a study for docs/robots.md.

    python bench/engine_delay.py [--delays 0 1 2 3] [--seconds 12]

Six TurtleBot3 Burgers in the physics engine (flock_swarm.engine) follow the circling leader of
examples/robots/tb3_fleet.yaml (Su 2009 protocol (10), the unicycle plant's conversion), with
no ROS: every control period each robot's law sees the robots' states ``delay`` periods old,
and its command integrates the law's acceleration from that (late) measured velocity
(``measured``: the plant's conversion, as sim does it), from the last command it sent
(``command``), or acts on the states predicted to the present (``predict``: the robot's own
through the commands it sent since, the others' at constant velocity,
flock_swarm.core.latency; the robot agent's and the agent nodes' default). Printed per delay
and way: the largest velocity mismatch with the leader at the end, the closest pair of axles,
and the pairs that touched.
"""

import argparse
import copy
import math
from pathlib import Path

import numpy as np
import yaml

from flock_swarm.core.latency import CommandHistory, extrapolate
from flock_swarm.core.laws.evaluation import local_control
from flock_swarm.core.leaders.base import LeaderState
from flock_swarm.core.robot_state import from_command, plant_state
from flock_swarm.core.scenario import realize
from flock_swarm.engine.mujoco_world import EngineWorld
from flock_swarm.presets import prepare

#: The fleet of the tests and docs/robots.md.
FLEET = yaml.safe_load((Path(__file__).resolve().parents[1] / 'examples' / 'robots'
                        / 'tb3_fleet.yaml').read_text())


def fly(delay: int, integrate_from: str, seconds: float) -> tuple[float, float, int]:
    """Return the final velocity mismatch, the closest axles and the pairs that touched."""
    sc, _ = prepare(copy.deepcopy(FLEET))
    real, plant, dt, n = realize(sc), sc.plant.model, sc.dt, sc.n_agents
    x0 = plant.initial_state(real.q0, real.p0)
    world = EngineWorld(x0[:, :2], 2 * np.arctan2(x0[:, 2], x0[:, 3]), speeds=x0[:, 4])
    a_matrix = np.array(FLEET['leader']['A'])
    lq, lp = np.array(FLEET['leader']['position']), np.array(FLEET['leader']['velocity'])
    history, sent = [], np.zeros((n, 2))
    commands = CommandHistory(plant)
    closest = math.inf
    for k in range(int(round(seconds / dt))):
        poses, vels = world.poses(), world.velocities()
        rows = np.array([plant_state(plant, 2, np.array([x, y, 0.0]),
                                     np.array([0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)]),
                                     np.array([vels[j, 0], vels[j, 1], 0.0]), vels[j, 2])
                         for j, (x, y, yaw) in enumerate(poses)])
        history.append((rows, lq.copy(), lp.copy()))
        seen, sq, sp = history[max(0, len(history) - 1 - delay)]
        if integrate_from == 'predict':
            # Every robot's own state through its commands, the neighbours' (in the law) at
            # constant velocity: both from the measurement's step to this one.
            age = min(delay, k) * dt
            own = commands.predict(seen, (k - min(delay, k)) * dt, k * dt)
            seen = extrapolate(plant, seen, age)
        q, p = plant.law_state(seen)
        leader = LeaderState(sq, sp, a_matrix @ sp)
        cmd = np.zeros((n, 2))
        for i in range(n):
            nb = [j for j in range(n) if j != i and np.linalg.norm(q[j] - q[i]) < sc.law.radius]
            if integrate_from == 'predict':
                q_i, p_i = (a[0] for a in plant.law_state(own[i:i + 1]))
            else:
                q_i, p_i = q[i], p[i]
            u = local_control(sc.law, q_i, p_i, q[nb], p[nb], np.ones(len(nb)), leader,
                              real.agents.subset(np.array([i])), dt)
            x = own[i:i + 1] if integrate_from == 'predict' else seen[i:i + 1]
            if integrate_from == 'command':
                x = from_command(plant.name, x, sent[i:i + 1])
            cmd[i] = plant.command(x, u[None], dt)[0]
        world.set_twists(cmd[:, 0], cmd[:, 1])
        world.step(dt)
        sent = cmd
        commands.sent(k * dt, cmd)
        # The leader's linear field p' = A p, integrated as the world does (Euler is enough
        # for the comparison: both ways see the same leader).
        lq, lp = lq + dt * lp, lp + dt * (a_matrix @ lp)
        d = np.linalg.norm(poses[:, None, :2] - poses[None, :, :2], axis=-1) + 9 * np.eye(n)
        closest = min(closest, float(d.min()))
    _, p = plant.law_state(rows)
    return float(np.linalg.norm(p - lp, axis=1).max()), closest, len(world.contacts_run)


def main() -> int:
    """Run the study and print one line per delay and way."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--delays', type=int, nargs='+', default=[0, 1, 2, 3])
    parser.add_argument('--seconds', type=float, default=12.0)
    args = parser.parse_args()
    for delay in args.delays:
        for way in ('measured', 'command', 'predict'):
            mismatch, closest, touched = fly(delay, way, args.seconds)
            print(f'delay {delay} periods ({delay * 50} ms)  integrate from {way:8s}  '
                  f'velocity mismatch {mismatch:.3f} m/s  closest axles {closest:.3f} m  '
                  f'pairs touched {touched}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
