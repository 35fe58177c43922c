"""The experiments of the reproduction, one module each (an ``EXPERIMENT``, an instance of an
:class:`~flock_swarm.reproduce.experiment.Experiment` subclass), found by
:mod:`flock_swarm.reproduce.catalogue`. A module without ``EXPERIMENT`` holds helpers shared by
several experiments."""
