"""The scoring profile's humanness and rules terms of each agent-step of an episode, for ``info``.

Each agent gets the running twins (:data:`learn.running_terms.RUNNING_TERMS`) of the profile's
terms; each step feeds them the rows the simulator recorded for the agent since the last call,
so a step's terms equal the evaluator's on the agent's full record at that row, and cost the same
late in an episode as early.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

from evaluator.scoring.profile import ScoringProfile
from learn.running_terms import RUNNING_TERMS
from sim.record import RecordRow


class _AgentTerms:
    def __init__(self, profile: ScoringProfile) -> None:
        names = (*profile.humanness_terms, *profile.rules_terms)
        # (name, the running term's bound update) of each term: no lookups per row
        self.updates: list[tuple[str, Callable[[RecordRow], float]]] = [
            (name, RUNNING_TERMS[name](profile).update) for name in names
        ]
        self.rows_seen = 0
        self.last: dict[str, float] = {}


class EpisodeTerms:
    """The running terms of every agent of one episode (a new one per episode)."""

    def __init__(self, profile: ScoringProfile) -> None:
        self._profile = profile
        self._agents: dict[str, _AgentTerms] = {}

    def step(self, agent_id: str, rows: Sequence[RecordRow]) -> dict[str, float]:
        """Every term of the newest of ``rows`` (the agent's record so far, oldest first: the
        rows not seen before are fed in order); empty before the agent has driven."""
        agent = self._agents.get(agent_id)
        if agent is None:
            agent = self._agents[agent_id] = _AgentTerms(self._profile)
        seen, count = agent.rows_seen, len(rows)
        for t in range(seen, count):
            row = rows[t]
            agent.last = {name: update(row) for name, update in agent.updates}
        agent.rows_seen = count
        return dict(agent.last)
