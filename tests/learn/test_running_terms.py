"""The env's running scoring terms equal the evaluator's terms on the full record, row by row.

Real episodes, each run once for the module: the planner through a junction and on a shared
curved road, seeded random actions among replayed traffic, and scripted rule breakers (an agent
speeding up past the limit behind a car, another driving against its lane). Each episode's
record rows are fed one at a time to a fresh running term and compared with the evaluator's term
on the record it wrote, for every registered term under every scoring profile; the per-step terms
the env reports (:class:`learn.terms.EpisodeTerms`, fed while the episode ran, as the env feeds
it) are compared the same way.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from arena.scenario import load_scenario
from arena.suite import SHIPPED_PUBLIC_DIR
from evaluator.scoring import load_profile
from evaluator.scoring.profile import profile_names
from evaluator.scoring.record import EpisodeRecord, load_record
from evaluator.scoring.registry import get_term, term_names
from learn.running_terms import RUNNING_TERMS
from learn.terms import EpisodeTerms
from scenarios.experts import PlannerAgent, planner_interface
from sim.interface import AgentInterface
from sim.record import RecordRow
from sim.simulation import Simulation
from tests.sim.builders import ScenarioSpec, lane_y, make_scenario, mission, vehicle_xml
from tests.sim.test_record_regression import _SeededRandom

# libm's and numpy's hypot, atan2 and exp may round the last place differently.
RTOL = 1e-12


@dataclass
class Episode:
    name: str
    record: EpisodeRecord
    rows: dict[str, list[RecordRow]]  # the simulator's own rows, by agent
    reported: dict[str, dict[str, list[dict[str, float]]]]  # profile -> agent -> per-row terms


def advance(speed_at):
    """A TargetPose policy: along the ego's heading at ``speed_at(step)`` [m/s]."""
    step = [0]

    def policy(obs: dict) -> list[float]:
        step[0] += 1
        x, y, _ = obs["ego_vehicle_state"]["position"]
        heading = float(obs["ego_vehicle_state"]["heading"])
        distance = speed_at(step[0]) * 0.1  # [m] in a 0.1 s step
        return [x + distance * math.cos(heading), y + distance * math.sin(heading), heading, 0.1]

    return policy


class PerAgent:
    """Each agent driven by its own policy."""

    def __init__(self, policies: dict) -> None:
        self.policies = policies

    def reset(self) -> None:
        pass

    def act(self, obs: dict[str, dict]) -> dict[str, list[float]]:
        return {agent_id: self.policies[agent_id](o) for agent_id, o in obs.items()}


def rule_breakers(root: Path) -> Path:
    """Agent_0 speeds up from 10 to 30 m/s (limit 13.89) behind a slow car; Agent_1 drives
    westwards in an eastward lane."""
    spec = ScenarioSpec(
        missions=(
            mission("Agent_0", start=(20.0, lane_y(1), 0.0), speed=10.0),
            mission("Agent_1", start=(300.0, lane_y(0), math.pi), goal=(20.0, lane_y(0))),
        ),
        vehicles=[vehicle_xml("slow", 120.0, 1, 5.0, vtype="steady")],
        max_episode_steps=60,
    )
    return make_scenario(root / "rule_breakers", spec)


def run(name: str, folder: Path, agent, interface: AgentInterface, out: Path) -> Episode:
    """One episode as :class:`learn.session.SimulatorSession` steps it: the terms of every
    agent that drove, after each step, under every profile."""
    terms = {p: EpisodeTerms(load_profile(p)) for p in profile_names()}
    reported = {p: {} for p in profile_names()}
    sim = Simulation(load_scenario(folder), folder, interface)
    try:
        obs = sim.reset()
        agent.reset()
        while not sim.done:
            drove = sim.step(agent.act({k: o for k, o in obs.items() if not o["done"]}))
            for agent_id in drove:
                for profile, episode_terms in terms.items():
                    step = episode_terms.step(agent_id, sim.recorder.rows[agent_id])
                    reported[profile].setdefault(agent_id, []).append(step)
            obs = drove
        sim.write_record(out / f"{name}.npz")
    finally:
        sim.close()
    return Episode(name, load_record(out / f"{name}.npz"), sim.recorder.rows, reported)


@pytest.fixture(scope="module")
def episodes(tmp_path_factory) -> list[Episode]:
    out = tmp_path_factory.mktemp("records")
    planner = planner_interface()
    breaking = PerAgent(
        {
            "Agent_0": advance(lambda step: min(10.0 + step * 0.5, 30.0)),
            "Agent_1": advance(lambda step: 8.0),
        }
    )
    cases = [
        ("junction", SHIPPED_PUBLIC_DIR / "p000_left_turn_t_low", PlannerAgent(), planner),
        (
            "curve",
            SHIPPED_PUBLIC_DIR / "p020_cruise_3lane_curve_low_3agents",
            PlannerAgent(),
            planner,
        ),
        (
            "random",
            SHIPPED_PUBLIC_DIR / "p030_replay_cruise",
            _SeededRandom("Continuous"),
            AgentInterface(action_space="Continuous", observation_radius=150.0),
        ),
        (
            "breakers",
            rule_breakers(tmp_path_factory.mktemp("scenarios")),
            breaking,
            AgentInterface(action_space="TargetPose"),
        ),
    ]
    return [run(name, folder, agent, interface, out) for name, folder, agent, interface in cases]


def test_every_registered_term_has_a_running_twin():
    assert sorted(RUNNING_TERMS) == sorted(term_names())


def test_the_episodes_exercise_every_term(episodes):
    """Every term is non-zero somewhere, so that the equalities below are not about zeros."""
    profile = load_profile()
    for name in term_names():
        values = [get_term(name)(t, profile) for e in episodes for t in e.record.tracks]
        assert any(v.any() for v in values), name


@pytest.mark.parametrize("profile_name", profile_names())
@pytest.mark.parametrize("term_name", term_names())
def test_running_term_equals_the_evaluators_on_the_record(episodes, term_name, profile_name):
    profile = load_profile(profile_name)
    for episode in episodes:
        for outcome, track in zip(episode.record.agents, episode.record.tracks, strict=True):
            running = RUNNING_TERMS[term_name](profile)
            got = [running.update(row) for row in episode.rows[outcome.id]]
            want = get_term(term_name)(track, profile)
            np.testing.assert_allclose(
                got, want, rtol=RTOL, atol=0, err_msg=f"{episode.name} {outcome.id}"
            )


@pytest.mark.parametrize("profile_name", profile_names())
def test_the_env_reports_the_profiles_terms_of_each_step(episodes, profile_name):
    profile = load_profile(profile_name)
    names = (*profile.humanness_terms, *profile.rules_terms)
    for episode in episodes:
        reported = episode.reported[profile_name]
        for outcome, track in zip(episode.record.agents, episode.record.tracks, strict=True):
            # An agent that entered gets its first observation, and empty terms, before it drove.
            steps = [step for step in reported.get(outcome.id, []) if step]
            assert len(steps) == len(track.x)  # one report per driven row
            for name in names:
                np.testing.assert_allclose(
                    [step[name] for step in steps],
                    get_term(name)(track, profile),
                    rtol=RTOL,
                    atol=0,
                    err_msg=f"{episode.name} {outcome.id} {name}",
                )
            assert all(set(step) == set(names) for step in steps)


def test_rows_not_reported_before_are_fed_in_order(episodes):
    """A step that recorded several rows for an agent (or a first call late in the episode)
    still gives the newest row's terms: every row is fed once, oldest first."""
    profile = load_profile("driving-smarts-2022-reference")
    episode = next(e for e in episodes if e.name == "curve")
    for outcome, track in zip(episode.record.agents, episode.record.tracks, strict=True):
        rows = episode.rows[outcome.id]
        terms = EpisodeTerms(profile)
        half = len(rows) // 2
        assert terms.step(outcome.id, []) == {}
        first = terms.step(outcome.id, rows[:half])
        last = terms.step(outcome.id, rows)
        for name in (*profile.humanness_terms, *profile.rules_terms):
            want = get_term(name)(track, profile)
            assert first[name] == pytest.approx(want[half - 1], rel=RTOL)
            assert last[name] == pytest.approx(want[-1], rel=RTOL)
