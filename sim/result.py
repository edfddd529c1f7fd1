"""The outcome of one episode as the evaluator sees it (the full per-step data is in the record)."""

from __future__ import annotations

from dataclasses import dataclass, field

from arena.outcome import AgentOutcome


@dataclass(frozen=True)
class EpisodeResult:
    scenario_id: str
    steps: int  # episode steps simulated
    agents: tuple[AgentOutcome, ...]
    record_path: str | None  # the .npz episode record, None if the simulator failed before any
    simulator_error: str | None = None  # set when SUMO failed: not charged to the participant
    detail: str = ""  # human-readable failure detail (traceback, agent stderr tail)
    wall_time_s: float = 0.0
    # CPU time of the agent's acts [s], as its handle measured it (0 where nothing measures it).
    agent_cpu_s: float = 0.0
    # Whether the agent was sent an observation: False when it failed while it was loaded
    # (import, __init__, init_timeout), before anything of the scenario reached it.
    observed: bool = True
    extra: dict = field(default_factory=dict)
