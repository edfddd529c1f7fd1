"""SMARTS's ``AgentSpec`` (``smarts.zoo.agent_spec``): an interface and how to build an agent."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from smarts.core.agent_interface import AgentInterface


@dataclass
class AgentSpec:
    interface: AgentInterface | None = None
    agent_builder: Callable[..., Any] | None = None
    agent_params: Any = None

    def build_agent(self):
        params = self.agent_params
        if params is None:
            return self.agent_builder()
        if isinstance(params, dict):
            return self.agent_builder(**params)
        return (
            self.agent_builder(*params)
            if isinstance(params, list | tuple)
            else (self.agent_builder(params))
        )
