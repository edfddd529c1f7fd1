"""Per-scenario results: the sums the suite metrics are built from."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from arena.errors import RecordError
from arena.outcome import AgentOutcome
from evaluator.scoring.profile import ScoringProfile
from evaluator.scoring.record import EpisodeRecord
from evaluator.scoring.registry import get_term


@dataclass(frozen=True)
class EpisodeScore:
    """One scenario's contribution to the suite metrics.

    Humanness and rules are kept as sums over agent-steps (not means) because the suite metric is
    a mean over every agent-step of the set, which per-scenario means cannot reproduce.
    """

    scenario_id: str
    failure: float  # fraction of mission agents that did not reach their goal, 0..1
    time: int  # [steps] last goal step, or max_episode_steps if any agent failed
    agent_steps: int  # agent-steps driven, over all agents
    humanness_sum: float
    rules_sum: float
    term_sums: dict[str, float]  # per term, over all agent-steps

    @property
    def humanness(self) -> float:
        return self.humanness_sum / self.agent_steps if self.agent_steps else 0.0

    @property
    def rules(self) -> float:
        return self.rules_sum / self.agent_steps if self.agent_steps else 0.0


def score_episode(record: EpisodeRecord, profile: ScoringProfile) -> EpisodeScore:
    if not np.isclose(record.dt, profile.dt_s):
        raise RecordError(
            f"{record.scenario_id}: record step {record.dt} s, profile {profile.name} expects "
            f"{profile.dt_s} s"
        )
    names = profile.humanness_terms + profile.rules_terms
    term_sums = {
        name: float(sum(get_term(name)(track, profile).sum() for track in record.tracks))
        for name in names
    }
    return _score(record.scenario_id, record.agents, term_sums, profile)


def score_without_record(
    scenario_id: str, agents: Sequence[AgentOutcome], profile: ScoringProfile
) -> EpisodeScore:
    """A scenario whose agent failed before driving a step (no record was written): charged as
    failed, contributing no agent-steps."""
    if any(agent.steps for agent in agents):
        raise RecordError(f"{scenario_id}: agents drove steps but the record is missing")
    names = profile.humanness_terms + profile.rules_terms
    return _score(scenario_id, agents, dict.fromkeys(names, 0.0), profile)


def _score(
    scenario_id: str,
    agents: Sequence[AgentOutcome],
    term_sums: dict[str, float],
    profile: ScoringProfile,
) -> EpisodeScore:
    if not agents:
        raise RecordError(f"{scenario_id}: no mission agents")
    failed = sum(not agent.reached_goal for agent in agents)
    time = profile.max_episode_steps if failed else max(agent.done_step for agent in agents)
    return EpisodeScore(
        scenario_id=scenario_id,
        failure=failed / len(agents),
        time=time,
        agent_steps=sum(agent.steps for agent in agents),
        humanness_sum=sum(term_sums[name] for name in profile.humanness_terms),
        rules_sum=sum(term_sums[name] for name in profile.rules_terms),
        term_sums=term_sums,
    )
