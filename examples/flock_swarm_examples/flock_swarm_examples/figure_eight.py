"""A virtual leader flying a figure eight: a Lissajous curve of frequency ratio 1:2.

The leader's position is ``q_gamma(t) = q_gamma(0) + (A sin(omega t), B sin(2 omega t))``
(plus a constant ``z`` in 3-D): a lemniscate-like figure eight of width ``2A`` and height
``2B`` through its start. As a leader model it is the time-dependent ODE

    p' = f(t) = (-A omega^2 sin(omega t), -4 B omega^2 sin(2 omega t)[, 0]),

which traces that curve when the scenario starts the leader with the matching velocity
``p_gamma(0) = (A omega, 2 B omega[, 0])``; any other start adds a constant drift.
"""

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from flock_swarm.plugin import LeaderModel, require


@dataclass(frozen=True)
class FigureEight(LeaderModel):
    """A figure-eight (Lissajous 1:2) path, ``p' = f(t)``.

    :ivar omega: angular frequency of the ``x`` motion [rad/s] (``y`` moves at twice it).
    :ivar width: half width ``A`` of the figure eight [m].
    :ivar height: half height ``B`` of the figure eight [m].
    """

    name: ClassVar[str] = 'figure_eight'
    citation: ClassVar[str] = ('figure eight: Lissajous curve 1:2, '
                               'q(t) = q(0) + (A sin wt, B sin 2wt)')
    autonomous: ClassVar[bool] = False

    omega: float = 0.2
    width: float = 10.0
    height: float = 5.0

    def validate(self, dim: int, prefix: str = 'leader.') -> None:
        """Check ``omega > 0``, ``width > 0`` and ``height > 0``."""
        require(self.omega > 0, prefix + 'omega', f'must be > 0, got {self.omega}')
        require(self.width > 0, prefix + 'width', f'must be > 0, got {self.width}')
        require(self.height > 0, prefix + 'height', f'must be > 0, got {self.height}')

    def acceleration(self, t: float, q: np.ndarray, p: np.ndarray) -> np.ndarray:
        """Return ``f(t)``, shaped like ``p`` (zero along ``z``)."""
        w = self.omega
        out = np.zeros_like(p, dtype=float)
        out[..., 0] = -self.width * w * w * np.sin(w * t)
        out[..., 1] = -4.0 * self.height * w * w * np.sin(2.0 * w * t)
        return out
