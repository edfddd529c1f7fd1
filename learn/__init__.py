"""The learning kit: Gymnasium and PettingZoo environments over the arena's own simulator.

``learn.gym_env.DrivingArenaEnv`` (one agent) and ``learn.parallel_env.DrivingArenaParallelEnv``
(1-3 agents) drive :class:`sim.simulation.Simulation` exactly as evaluation does, through a
``learn.session`` in their own process or in a child process (``learn.worker``). See
``docs/training.md``.
"""
