"""What an environment and its simulator exchange, wherever the simulator runs (in this process,
:mod:`learn.session`, or in a child, :mod:`learn.worker`): the configuration, the reply of each
reset and step, and the interface both kinds of simulator offer."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal, Protocol

SimulatorMode = Literal["auto", "in_process", "subprocess"]
SIMULATOR_MODES = ("auto", "in_process", "subprocess")


@dataclass(frozen=True)
class Config:
    interface: Any  # sim.interface.AgentInterface
    profile: str  # scoring profile whose terms go into info


@dataclass
class Reply:
    """What one reset or step produced."""

    # Observations as arrays (learn.spaces); a child process sends their records (bytes of
    # sim.observation_arrays.ObservationLayout).
    observations: dict[str, Any]  # of the agents live after the step
    finished: dict[str, str] = field(default_factory=dict)  # agent id -> done reason
    terminal: dict[str, Any] = field(default_factory=dict)  # of the agents finished this step
    events: dict[str, dict] = field(default_factory=dict)  # of every agent that drove this step
    terms: dict[str, dict[str, float]] = field(default_factory=dict)
    ids: dict[str, dict[str, str]] = field(default_factory=dict)  # road/lane ids per agent
    done: bool = False  # the episode is over for everyone
    scenario_id: str = ""
    step: int = 0


class Simulator(Protocol):
    """What an environment drives: a session here or one in a child process."""

    def reset(self, scenario_dir: str, seed: int | None) -> Reply: ...

    def step(self, actions: dict[str, Any]) -> Reply: ...

    def close(self) -> None: ...


def check_simulator_mode(mode: str) -> None:
    if mode not in SIMULATOR_MODES:
        raise ValueError(f"simulator is one of {', '.join(SIMULATOR_MODES)}, not {mode!r}")
