"""Scoring profiles: every constant of the scoring spec in one named, versioned file.

Profiles live in ``evaluator/scoring/profiles/<name>.json``. A misspelt key, a term name that is
not registered, or a term listed twice fails when the profile loads, not halfway through scoring.
"""

from __future__ import annotations

from enum import StrEnum
from functools import cache
from importlib import resources

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    field_validator,
    model_validator,
)

from arena.errors import ArenaError
from evaluator.scoring.registry import get_term

DEFAULT_PROFILE = "driving-smarts-2022"


class ProfileError(ArenaError, ValueError):
    pass


class Averaging(StrEnum):
    """How humanness and rules are averaged over a set of scenarios."""

    # The paper: every agent-step weighs the same (long episodes weigh more).
    agent_step = "agent_step"
    # The competition's evaluation code: each agent-episode's mean first, then the mean of those.
    agent_episode = "agent_episode"


class ScoringProfile(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")

    name: str
    version: int = Field(ge=1)
    description: str = ""

    dt_s: float = Field(gt=0)  # step length the records must have [s]
    max_episode_steps: int = Field(gt=0)  # time charged to a scenario with a failed agent

    humanness_terms: tuple[str, ...]
    rules_terms: tuple[str, ...]

    obs_headway_s: float = Field(gt=0)  # distance_obs looks this many seconds of speed ahead
    obs_half_angle_deg: float = Field(gt=0, le=180)  # ... within this angle of the heading
    obs_decay_per_m: float = Field(gt=0)  # exp(-decay * d)
    speeding_tolerance_fraction: float = Field(gt=0)  # speeding saturates at (1 + f) x limit
    wrong_way_angle_deg: float = Field(gt=0, le=180)

    averaging: Averaging = Averaging.agent_step
    # With agent_episode averaging: terms whose per-step values are running means, so an
    # agent-episode keeps the value of its last step instead of the mean of its steps.
    last_value_terms: tuple[str, ...] = ()
    # Time adds sum over agents of |x - goal_x| + |y - goal_y| [m] at the agent's last row.
    time_adds_goal_l1: bool = False

    @field_validator("humanness_terms", "rules_terms")
    @classmethod
    def _registered_once(cls, names: tuple[str, ...]) -> tuple[str, ...]:
        if len(set(names)) != len(names):
            raise ValueError(f"a term is listed twice: {list(names)}")
        for name in names:
            get_term(name)  # raises on an unknown name
        return names

    @model_validator(mode="after")
    def _last_value_terms_are_scored(self) -> ScoringProfile:
        unknown = set(self.last_value_terms) - set(self.humanness_terms + self.rules_terms)
        if unknown:
            raise ValueError(f"last_value_terms not in the profile's terms: {sorted(unknown)}")
        if self.last_value_terms and self.averaging is not Averaging.agent_episode:
            raise ValueError("last_value_terms needs averaging = agent_episode")
        return self

    @property
    def ref(self) -> dict[str, str | int]:
        return {"name": self.name, "version": self.version}


def profile_names() -> tuple[str, ...]:
    folder = resources.files("evaluator.scoring") / "profiles"
    return tuple(sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith(".json")))


@cache
def load_profile(name: str = DEFAULT_PROFILE) -> ScoringProfile:
    if name not in profile_names():
        known = ", ".join(profile_names())
        raise ProfileError(f"unknown scoring profile {name!r} (known: {known})")
    text = (resources.files("evaluator.scoring") / "profiles" / f"{name}.json").read_text()
    try:
        profile = ScoringProfile.model_validate_json(text)
    except ValidationError as exc:
        raise ProfileError(f"scoring profile {name!r} is invalid: {exc}") from exc
    if profile.name != name:
        raise ProfileError(f"profile file {name}.json names itself {profile.name!r}")
    return profile
