"""Where SMARTS before 0.6 kept ``AgentSpec`` and ``Agent`` (``smarts.core.agent``)."""

from smarts.zoo.agent_spec import AgentSpec


class Agent:
    """The base class SMARTS agents derive from: ``act(obs)`` returns an action."""

    def act(self, obs):
        raise NotImplementedError


__all__ = ["Agent", "AgentSpec"]
