"""What the simulator needs from whatever drives the mission vehicles.

The evaluator's sandboxed agent handles and in-process test policies both satisfy :class:`Agent`.
A failure of the agent itself (not of one action) is raised as :class:`arena.errors.AgentFailed`.
An agent with a true ``takes_arrays`` attribute (a sandbox handle of ``observation_format:
arrays``) is given :class:`sim.observation_record.ArraysObservation` values, the records the
simulator writes in place, instead of observation dicts. One with a true
``takes_packed_waypoints`` (a sandbox handle of the other formats) is given observation dicts whose
``waypoint_paths`` are packed for the protocol (:mod:`agent_runtime.packed_waypoints`): its runtime
makes them the dicts an in-process agent gets. One with a true ``takes_agent_ids`` (a sandbox
handle) is reset with ``reset(agent_ids)``: every mission's agent id of the episode, those that
start later included, which SMARTS's wrappers learn when they are built.

An exception of the agent's ends every still-live agent of the episode: the agent drives them all
(``docs/protocol.md``, "An exception in act").
"""

from __future__ import annotations

from typing import Any, Protocol

Observation = dict[str, Any]
Action = list[float]


class Agent(Protocol):
    def reset(self) -> None:
        """A new episode starts."""

    def act(self, obs: dict[str, Observation]) -> dict[str, Any]:
        """One action per agent id in ``obs``. May raise :class:`arena.errors.AgentFailed`."""

    def close(self) -> None:
        """Release the agent (process, container)."""
