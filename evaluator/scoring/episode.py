"""Per-scenario results: the sums the suite metrics are built from."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from arena.errors import RecordError
from arena.outcome import AgentOutcome
from evaluator.scoring.profile import Averaging, ScoringProfile
from evaluator.scoring.record import AgentTrack, EpisodeRecord
from evaluator.scoring.registry import get_term


@dataclass(frozen=True)
class EpisodeScore:
    """One scenario's contribution to the suite metrics.

    Humanness and rules are kept as sums over agent-steps (not means) because the suite metric is
    a mean over every agent-step of the set, which per-scenario means cannot reproduce.
    """

    scenario_id: str
    failure: float  # fraction of mission agents that did not reach their goal, 0..1
    # [steps] last goal step, or max_episode_steps if any agent failed (plus the goal L1
    # distances [m] under a profile with time_adds_goal_l1)
    time: float
    # Agent-steps driven, over all agents (a mean over episodes in :func:`mean_score`).
    agent_steps: float
    humanness_sum: float
    rules_sum: float
    term_sums: dict[str, float]  # per term, over all agent-steps
    # With agent_episode averaging the sums are of per-agent-episode means and this counts the
    # agent-episodes that drove a step; the suite then divides by it instead of agent_steps.
    agent_episodes: float | None = None

    @property
    def weight(self) -> float:
        """What humanness_sum and rules_sum are averaged over."""
        return self.agent_steps if self.agent_episodes is None else self.agent_episodes

    @property
    def humanness(self) -> float:
        return self.humanness_sum / self.weight if self.weight else 0.0

    @property
    def rules(self) -> float:
        return self.rules_sum / self.weight if self.weight else 0.0


def score_episode(record: EpisodeRecord, profile: ScoringProfile) -> EpisodeScore:
    if not np.isclose(record.dt, profile.dt_s):
        raise RecordError(
            f"{record.scenario_id}: record step {record.dt} s, profile {profile.name} expects "
            f"{profile.dt_s} s"
        )
    names = profile.humanness_terms + profile.rules_terms
    if profile.averaging is Averaging.agent_episode:
        driven = [track for track in record.tracks if len(track.x)]
        term_sums = {
            name: float(sum(_per_agent_episode(name, track, profile) for track in driven))
            for name in names
        }
        return _score(
            record.scenario_id, record.agents, term_sums, profile, len(driven), goal_l1(record)
        )
    term_sums = {
        name: float(sum(get_term(name)(track, profile).sum() for track in record.tracks))
        for name in names
    }
    return _score(record.scenario_id, record.agents, term_sums, profile, None, goal_l1(record))


def mean_score(scores: Sequence[EpisodeScore]) -> EpisodeScore:
    """One scenario's score from its episodes: every field the mean over them. Sums and weights
    are averaged alike, so each scenario weighs in the suite as one episode does (a scenario run
    50 times does not drown one run once) and its humanness stays a mean over agent-steps."""
    if len(scores) == 1:
        return scores[0]
    n = len(scores)

    def mean(values) -> float:
        return sum(values) / n

    episodes = [s.agent_episodes for s in scores]
    return EpisodeScore(
        scenario_id=scores[0].scenario_id,
        failure=mean(s.failure for s in scores),
        time=mean(s.time for s in scores),
        agent_steps=mean(s.agent_steps for s in scores),
        humanness_sum=mean(s.humanness_sum for s in scores),
        rules_sum=mean(s.rules_sum for s in scores),
        term_sums={name: mean(s.term_sums[name] for s in scores) for name in scores[0].term_sums},
        agent_episodes=None if episodes[0] is None else mean(episodes),
    )


def _per_agent_episode(name: str, track: AgentTrack, profile: ScoringProfile) -> float:
    values = get_term(name)(track, profile)
    return float(values[-1] if name in profile.last_value_terms else values.mean())


def score_without_record(
    scenario_id: str, agents: Sequence[AgentOutcome], profile: ScoringProfile
) -> EpisodeScore:
    """A scenario whose agent failed before driving a step (no record was written): charged as
    failed, contributing no agent-steps."""
    if any(agent.steps for agent in agents):
        raise RecordError(f"{scenario_id}: agents drove steps but the record is missing")
    names = profile.humanness_terms + profile.rules_terms
    episodes = 0 if profile.averaging is Averaging.agent_episode else None
    return _score(scenario_id, agents, dict.fromkeys(names, 0.0), profile, episodes)


def _score(
    scenario_id: str,
    agents: Sequence[AgentOutcome],
    term_sums: dict[str, float],
    profile: ScoringProfile,
    agent_episodes: int | None = None,
    goal_distance: float = 0.0,
) -> EpisodeScore:
    if not agents:
        raise RecordError(f"{scenario_id}: no mission agents")
    failed = sum(not agent.reached_goal for agent in agents)
    time: float = profile.max_episode_steps if failed else max(a.done_step for a in agents)
    if profile.time_adds_goal_l1:
        time += goal_distance
    return EpisodeScore(
        scenario_id=scenario_id,
        failure=failed / len(agents),
        time=time,
        agent_steps=sum(agent.steps for agent in agents),
        humanness_sum=sum(term_sums[name] for name in profile.humanness_terms),
        rules_sum=sum(term_sums[name] for name in profile.rules_terms),
        term_sums=term_sums,
        agent_episodes=agent_episodes,
    )


def goal_l1(record: EpisodeRecord) -> float:
    """Sum over agents of ``|x - goal_x| + |y - goal_y|`` [m] at the agent's last driven row; 0
    for an agent that never drove (its start is not in the record; it is charged the step limit
    anyway)."""
    return sum(
        abs(float(track.x[-1]) - gx) + abs(float(track.y[-1]) - gy)
        for track, (gx, gy) in zip(record.tracks, record.goals, strict=True)
        if len(track.x)
    )
