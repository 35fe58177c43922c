"""Jadbabaie, Lin, Morse 2003: nearest-neighbour heading alignment with a leader, (38).

A. Jadbabaie, J. Lin, A. S. Morse, "Coordination of Groups of Mobile Autonomous Agents Using
Nearest Neighbor Rules", IEEE TAC 48(6), 2003 ([Jadbabaie03]).
"""

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from flock_swarm.core.checks import require
from flock_swarm.core.laws.base import Law


@dataclass(frozen=True)
class JadbabaieLeader(Law):
    """[Jadbabaie03] eq. (38): Vicsek heading average, the leader counted when within ``r``.

    Agents move at the common speed ``speed``; headings live in ``[0, 2 pi)`` as in the paper.
    In the double-integrator world each agent commands the acceleration that reaches the
    averaged velocity ``speed (cos theta, sin theta)`` in one step: ``u = (target - p) / dt``.

    :ivar r: neighbourhood radius (``<= r``).
    :ivar speed: common constant speed ``v``.
    """

    name: ClassVar[str] = 'jadbabaie_leader'
    citation: ClassVar[str] = ('Jadbabaie, Lin, Morse 2003, eq. (38): Vicsek headings with a '
                               'leader')
    antisymmetric: ClassVar[bool] = False
    strict_radius: ClassVar[bool] = False
    graph_types: ClassVar[tuple[str, ...]] = ('disk',)

    r: float = 1.0
    speed: float = 1.0

    @property
    def radius(self) -> float:
        """Return ``r``."""
        return self.r

    def validate(self, ctx):
        """Check ``dim = 2`` (headings are planar), ``r > 0`` and ``speed > 0``."""
        require(ctx.dim == 2, 'dim', 'jadbabaie_leader is a planar (dim = 2) heading model')
        require(self.r > 0, 'protocol.r', f'must be > 0, got {self.r}')
        require(self.speed > 0, 'protocol.speed', f'must be > 0, got {self.speed}')

    def pair(self, qi, pi, qj, pj, w):
        """Return ``(theta_j, 1)``: neighbour heading and a count, summed over neighbours."""
        return np.stack((heading(pj), np.ones(pj.shape[0])), axis=-1)

    def combine(self, q, p, s, leader, agents, dt, t=0.0):
        """Average ``theta_i``, the neighbours' and (when within ``r``) ``theta_0``; eq. (38)."""
        if leader is None:
            b, theta_0 = np.zeros(q.shape[0]), 0.0
        else:
            gap = q - leader.q
            b = (np.einsum('nk,nk->n', gap, gap) <= self.r * self.r).astype(float)
            theta_0 = heading(leader.p[None, :])
        theta = (heading(p) + s[:, 0] + b * theta_0) / (1.0 + s[:, 1] + b)
        target = self.speed * np.stack((np.cos(theta), np.sin(theta)), axis=-1)
        return (target - p) / dt


def heading(p: np.ndarray) -> np.ndarray:
    """Return the heading of 2-D velocities in ``[0, 2 pi)`` ([Jadbabaie03] Section II).

    :param p: velocities, shape ``(n, 2)``.
    :return: angles, shape ``(n,)``.
    """
    theta = np.mod(np.arctan2(p[:, 1], p[:, 0]), 2.0 * np.pi)
    # mod() rounds tiny negative angles up to exactly 2 pi, outside [0, 2 pi).
    return np.where(theta >= 2.0 * np.pi, 0.0, theta)
