"""flock_swarm: a swarm of double-integrator agents flocking behind a virtual leader."""

__version__ = '0.1.0'
