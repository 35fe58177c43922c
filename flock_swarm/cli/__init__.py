"""The commands: one thin module each (argparse, one call into a library, the exit status).

=============  ==========================================  =================================
command        module                                      library underneath
=============  ==========================================  =================================
``sim``        :mod:`flock_swarm.cli.sim`                  :mod:`flock_swarm.core.run`,
                                                           :mod:`flock_swarm.outputs`
``swarm``      :mod:`flock_swarm.cli.swarm`                :mod:`flock_swarm.nodes.swarm_runner`
``sweep``      :mod:`flock_swarm.cli.sweep`                :mod:`flock_swarm.study`
``analyze``    :mod:`flock_swarm.cli.analyze`              :mod:`flock_swarm.analysis`
``replay``     :mod:`flock_swarm.cli.replay`               :mod:`flock_swarm.nodes.player`
reproduction   :mod:`flock_swarm.cli.reproduce`            :mod:`flock_swarm.reproduce`
=============  ==========================================  =================================

Each runs as its console script or as ``python -m flock_swarm.cli.NAME`` (the reproduction as
``python -m flock_swarm.reproduce``). The node executables (``world``, ``leader``, ``agent``,
``agents``, ``foxglove_server``) keep their ``main`` in their node module. Nothing outside
this package imports it: the plumbing the commands share with the nodes (exit statuses,
one-line argument errors) is :mod:`flock_swarm.console`.
"""
