"""The agent's CPU limits, one value every layer passes along: an act's, an episode's and a
whole evaluation's (docs/protocol.md, "Time limits").

They count the agent's own CPU time, read from the host, so a busy worker changes no score. The
settings give the defaults (``step_cpu_s``, ``episode_cpu_s``, ``evaluation_cpu_s``); a phase may
override each, and an evaluation run records the three it was evaluated under.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class CpuLimits:
    step_s: float  # one act [s]
    episode_s: float  # one episode, from the agent's loading (init, reset, acts, close) [s]
    evaluation_s: float  # every episode of one evaluation together [s]

    def overridden(
        self,
        step_s: float | None = None,
        episode_s: float | None = None,
        evaluation_s: float | None = None,
    ) -> CpuLimits:
        """These limits with each given one replaced (None keeps this one's)."""
        return CpuLimits(
            step_s=self.step_s if step_s is None else step_s,
            episode_s=self.episode_s if episode_s is None else episode_s,
            evaluation_s=self.evaluation_s if evaluation_s is None else evaluation_s,
        )

    def over_budget(self, used_s: float) -> bool:
        return used_s > self.evaluation_s

    def budget_exceeded(self, used_s: float, episodes: int | None) -> str:
        """What the team is told when its agent's CPU passed the evaluation's budget: how much,
        where the episodes stopped (None: not told, in a hidden phase), and what to change."""
        where = f" in {episodes} episode(s)" if episodes is not None else ""
        return (
            f"your agent used {used_s:.1f} s of CPU{where}, over this "
            f"evaluation's budget of {self.evaluation_s:g} s, so the remaining episodes were "
            f"not run. Make the policy's act() cheaper (each act may use {self.step_s:g} s, "
            f"each episode {self.episode_s:g} s; `arena evaluate` shows the CPU it used) "
            "and submit again"
        )
