"""Run one episode in this process: scenario + agent -> outcomes and the episode record."""

from __future__ import annotations

import time
import traceback
from pathlib import Path
from typing import TYPE_CHECKING

from arena.errors import AgentFailed
from arena.outcome import DoneReason
from arena.scenario import load_scenario
from sim.agent import Agent
from sim.interface import AgentInterface
from sim.result import EpisodeResult
from sim.simulation import Simulation

if TYPE_CHECKING:
    from sim.inputs import ScenarioInputs


def run_episode(
    scenario_dir: Path,
    agent: Agent,
    interface: AgentInterface,
    *,
    record_path: Path,
    seed: int | None = None,
    wall_timeout_s: float | None = None,
    inputs: ScenarioInputs | None = None,
) -> EpisodeResult:
    """Drive ``scenario_dir``'s mission vehicles with ``agent`` until every one is done or the
    step limit; write the record to ``record_path`` (always, even with no rows).

    Calls ``agent.reset()`` first and never ``agent.close()`` (the caller owns the agent). An
    :class:`AgentFailed` (from ``reset`` or ``act``) ends every still-live agent with its reason,
    and so does any other exception of an in-process agent (``agent_error``); a bad action ends
    only its agent (``invalid_action``); passing ``wall_timeout_s`` ends the rest with
    ``episode_timeout``. ``inputs`` are the scenario's files already parsed
    (:mod:`sim.inputs`).
    SUMO errors propagate (the isolated runner turns them into ``simulator_error``).
    """
    started = time.monotonic()
    scenario = load_scenario(scenario_dir)
    sim = Simulation(
        scenario,
        scenario_dir,
        interface,
        seed,
        inputs=inputs,
        arrays=bool(getattr(agent, "takes_arrays", False)),  # see sim.agent
        packed_waypoints=bool(getattr(agent, "takes_packed_waypoints", False)),
    )
    detail = ""
    try:
        obs = sim.reset()
        detail = _reset_agent(agent, sim)
        while not sim.done:  # a failed reset ended every mission
            if wall_timeout_s is not None and time.monotonic() - started > wall_timeout_s:
                sim.fail(DoneReason.episode_timeout)
                detail = f"episode exceeded {wall_timeout_s:.0f} s wall time"
                break
            try:
                actions = agent.act(obs) if obs else {}
            except AgentFailed as exc:
                sim.fail(exc.reason)
                detail = exc.detail or str(exc)
                break
            except Exception as exc:  # an in-process policy's own bug is the agent's failure
                sim.fail(DoneReason.agent_error)
                detail = describe_exception(exc)
                break
            if not isinstance(actions, dict):
                sim.fail(DoneReason.invalid_action)
                detail = f"act() returned {type(actions).__name__}, expected a dict"
                break
            obs = sim.step(actions)
        if not detail and sim.violations:
            detail = "; ".join(sim.violations.values())
        sim.write_record(record_path)
    finally:
        sim.close()
    return EpisodeResult(
        scenario_id=scenario.id,
        steps=sim.step_count,
        agents=sim.outcomes,
        record_path=str(record_path),
        detail=detail,
        wall_time_s=time.monotonic() - started,
    )


def _reset_agent(agent: Agent, sim: Simulation) -> str:
    """Reset the agent; a failure of its own (raising, timing out, exiting) ends every mission
    with its reason, as in ``act``: the agent's, so charged. Why it failed, or "" if it did not."""
    try:
        if getattr(agent, "takes_agent_ids", False):  # see sim.agent
            agent.reset([v.id for v in sim.vehicles])
        else:
            agent.reset()
    except AgentFailed as exc:
        sim.fail(exc.reason)
        return exc.detail or str(exc)
    except Exception as exc:  # an in-process policy's own bug is the agent's failure
        sim.fail(DoneReason.agent_error)
        return describe_exception(exc)
    return ""


def describe_exception(exc: BaseException) -> str:
    """Last lines of a traceback: enough to diagnose, short enough to store."""
    return "".join(traceback.format_exception(exc))[-4000:]
