"""The learning kit: Gymnasium and PettingZoo environments over the arena's own simulator.

``learn.gym_env.DrivingArenaEnv`` (one agent) and ``learn.parallel_env.DrivingArenaParallelEnv``
(1-3 agents) drive :class:`sim.simulation.Simulation` in a child process each
(``learn.worker``), exactly as evaluation does. See ``docs/training.md``.
"""
