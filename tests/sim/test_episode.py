"""Episodes end to end in this process: determinism, failures, observations."""

import json

import numpy as np
import pytest

from arena.errors import AgentFailed
from arena.outcome import DoneReason
from arena.scenario import LaneChangeTrigger
from sim.interface import ActionSpace
from tests.sim.agents import ScriptedAgent, drive_straight
from tests.sim.builders import ScenarioSpec, lane_y, make_scenario, mission, straight_road

FLOW = (
    '<flow id="f" type="car" route="east" begin="0" end="60" vehsPerHour="1500" '
    'departLane="random" departSpeed="random" departPos="random_free"/>'
)


def busy(folder, **kwargs):
    spec = ScenarioSpec(
        missions=(mission(start=(20.0, lane_y(1), 0.0), goal=(390.0, lane_y(1))),),
        vehicles=[FLOW],
        max_episode_steps=200,
        **kwargs,
    )
    return make_scenario(folder, spec)


def test_same_seed_gives_byte_identical_records_other_seed_differs(tmp_path, run):
    folder = busy(tmp_path / "busy")
    first = run(folder, drive_straight(8.0), record="a.npz")
    second = run(folder, drive_straight(8.0), record="b.npz")
    other = run(folder, drive_straight(8.0), record="c.npz", seed=2)
    records = tmp_path / "busy-records"
    assert (records / "a.npz").read_bytes() == (records / "b.npz").read_bytes()
    assert first.record["nbr_valid"].sum() > 100  # there was traffic to compare
    assert int(first.record["seed"]) == 1 and int(other.record["seed"]) == 2
    assert (records / "a.npz").read_bytes() != (records / "c.npz").read_bytes()
    a, c = first.record, other.record
    assert a["nbr_id"].shape != c["nbr_id"].shape or not np.array_equal(a["nbr_x"], c["nbr_x"])
    assert second.result.agents == first.result.agents


def test_two_episodes_in_a_row_leak_no_state(tmp_path, run):
    a = busy(tmp_path / "a")
    b = make_scenario(
        tmp_path / "b",
        ScenarioSpec(vehicles=[FLOW.replace('id="f"', 'id="g"')], max_episode_steps=120, seed=5),
    )
    run(a, drive_straight(8.0), record="1.npz")
    run(b, drive_straight(12.0), record="2.npz")
    run(a, drive_straight(8.0), record="3.npz")
    records = tmp_path / "a-records"
    assert (records / "1.npz").read_bytes() == (records / "3.npz").read_bytes()


def test_invalid_action_fails_only_that_agent(tmp_path, run):
    folder = make_scenario(
        tmp_path,
        ScenarioSpec(
            missions=(
                mission("Agent_0", start=(20.0, lane_y(1), 0.0)),
                mission("Agent_1", start=(20.0, lane_y(0), 0.0), goal=(80.0, lane_y(0))),
            )
        ),
    )

    def policy(obs):
        state = obs["ego_vehicle_state"]
        if state["id"] == "Agent_0" and obs["step_count"] == 5:
            return [float("nan"), 0.0, 0.0, 0.1]
        return drive_straight(10.0)(obs)

    r = run(folder, policy)
    by_id = {o.id: o for o in r.result.agents}
    assert by_id["Agent_0"].reason is DoneReason.invalid_action
    assert by_id["Agent_0"].steps == 5 and by_id["Agent_0"].done_step == 6
    assert by_id["Agent_1"].reason is DoneReason.reached_goal
    assert list(r.record["steps"]) == [5, by_id["Agent_1"].steps]
    assert r.record["valid"][0].sum() == 5
    assert list(r.record["done_reason"]) == ["invalid_action", "reached_goal"]
    # Each agent sees the other as a neighbour.
    assert "Agent_1" in [n["id"] for n in r.agent.seen[0]["Agent_0"]["neighborhood_vehicle_states"]]


def test_agent_failure_ends_the_episode_keeping_driven_steps(tmp_path, run):
    folder = make_scenario(tmp_path, ScenarioSpec())

    def policy(obs):
        if obs["step_count"] == 3:
            raise AgentFailed(DoneReason.step_timeout, "act took 1.4 s")
        return drive_straight(10.0)(obs)

    r = run(folder, policy)
    assert r.outcome.reason is DoneReason.step_timeout and r.outcome.steps == 3
    assert r.result.detail == "act took 1.4 s"
    assert list(r.record["done_reason"]) == ["step_timeout"]


def test_step_limit_and_start_delay(tmp_path, run):
    folder = make_scenario(
        tmp_path,
        ScenarioSpec(
            missions=(mission(start_step=10, goal=(390.0, lane_y(1))),), max_episode_steps=40
        ),
    )
    r = run(folder, drive_straight(2.0))
    assert r.outcome.reason is DoneReason.max_episode_steps
    assert r.outcome.steps == 30 and r.result.steps == 40
    assert r.agent.seen[0]["Agent_0"]["step_count"] == 10
    assert list(r.record["step"][0, [0, -1]]) == [11, 40]
    assert r.agent.seen[-1]["Agent_0"]["step_count"] == 39


def test_observation_has_every_field_of_the_spec(tmp_path, run):
    folder = busy(tmp_path)
    r = run(folder, drive_straight(8.0))
    obs = r.agent.seen[10]["Agent_0"]
    assert set(obs) == {
        "dt",
        "step_count",
        "elapsed_sim_time",
        "distance_travelled",
        "done",
        "events",
        "ego_vehicle_state",
        "neighborhood_vehicle_states",
        "waypoint_paths",
    }
    assert set(obs["events"]) == {
        "collisions",
        "off_road",
        "off_route",
        "on_shoulder",
        "wrong_way",
        "not_moving",
        "reached_goal",
        "reached_max_episode_steps",
    }
    ego = obs["ego_vehicle_state"]
    assert set(ego) == {
        "id",
        "position",
        "heading",
        "speed",
        "bounding_box",
        "steering",
        "yaw_rate",
        "road_id",
        "lane_id",
        "lane_index",
        "lane_position",
        "linear_velocity",
        "angular_velocity",
        "linear_acceleration",
        "angular_acceleration",
        "linear_jerk",
        "angular_jerk",
        "mission",
    }
    assert ego["position"][0] == pytest.approx(20.0 + 8.0)
    assert ego["linear_velocity"][:2] == pytest.approx([8.0, 0.0])
    assert obs["distance_travelled"] == pytest.approx(8.0)
    assert obs["elapsed_sim_time"] == pytest.approx(1.0)
    assert ego["mission"]["goal"] == {"position": [390.0, lane_y(1)], "radius": 2.0}
    nbrs = obs["neighborhood_vehicle_states"]
    assert nbrs and set(nbrs[0]) == {
        "id",
        "position",
        "heading",
        "speed",
        "bounding_box",
        "road_id",
        "lane_id",
        "lane_index",
    }
    d = [
        np.hypot(n["position"][0] - ego["position"][0], n["position"][1] - ego["position"][1])
        for n in nbrs
    ]
    assert d == sorted(d) and max(d) <= 100.0
    assert len(obs["waypoint_paths"]) == 2 and len(obs["waypoint_paths"][1]) == 50


def test_lane_controller_changes_lane(tmp_path, run):
    folder = make_scenario(
        tmp_path,
        ScenarioSpec(
            missions=(mission(start=(20.0, lane_y(0), 0.0), goal=(390.0, lane_y(1))),),
            max_episode_steps=80,
        ),
    )

    def go_left(obs):
        return [10.0, 1.0 if obs["step_count"] == 5 else 0.0]

    r = run(folder, go_left, ActionSpace.LaneWithContinuousSpeed)
    rec = r.record
    assert rec["lane_id"][0, 0] == "E_0" and rec["lane_id"][0, -1] == "E_1"
    assert abs(rec["lane_offset"][0, -1]) < 0.2
    assert rec["speed"][0, -1] == pytest.approx(10.0, abs=0.3)


def test_cut_in_trigger_forces_the_lane_change(tmp_path, run):
    folder = make_scenario(
        tmp_path,
        ScenarioSpec(
            missions=(
                mission(start=(30.0, lane_y(1, 3), 0.0), goal=(390.0, lane_y(1, 3)), speed=10.0),
            ),
            vehicles=[
                '<vType id="slow" sigma="0" speedDev="0" maxSpeed="8"/>'
                '<vehicle id="cutter" type="slow" route="east" depart="0" departPos="70" '
                'departLane="0" departSpeed="8"/>'
            ],
            triggers=(LaneChangeTrigger(vehicle="cutter", agent_id="Agent_0", gap_m=30.0),),
            net=lambda f: straight_road(f, lanes=3),
            max_episode_steps=60,
        ),
    )
    r = run(folder, drive_straight(10.0))

    def cutter_lane(obs):
        return next(
            n["lane_index"]
            for n in obs["Agent_0"]["neighborhood_vehicle_states"]
            if n["id"] == "cutter"
        )

    lanes = [cutter_lane(o) for o in r.agent.seen]
    assert lanes[0] == 0 and 1 in lanes


def test_the_others_drive_on_after_one_agent_is_removed(tmp_path, run):
    folder = make_scenario(
        tmp_path,
        ScenarioSpec(
            missions=(
                mission("Agent_0", start=(20.0, lane_y(0), 0.0)),
                mission("Agent_1", start=(20.0, lane_y(1), 0.0), goal=(120.0, lane_y(1))),
            ),
            vehicles=[FLOW],
        ),
    )

    def policy(obs):
        x, y, _ = obs["ego_vehicle_state"]["position"]
        if obs["ego_vehicle_state"]["id"] == "Agent_0":
            return [x + 1.0, y - 0.5, -0.5, 0.1]  # off the right edge within a few steps
        return [x + 1.0, y, 0.0, 0.1]

    r = run(folder, policy)
    by_id = {o.id: o for o in r.result.agents}
    assert by_id["Agent_0"].reason is DoneReason.off_road and by_id["Agent_0"].steps < 10
    assert by_id["Agent_1"].reason is DoneReason.reached_goal
    late = r.agent.seen[-1]["Agent_1"]["neighborhood_vehicle_states"]
    assert "Agent_0" not in [n["id"] for n in late]


def test_finishing_agent_gets_its_last_observation_then_is_nobodys_neighbour(tmp_path, run):
    """Two agents side by side; Agent_0 drives off the road. The step it ends, it receives its
    last observation (off_road event, done) while Agent_1 may still see it; from the next step
    on it appears neither in the observations nor among Agent_1's neighbours."""
    folder = make_scenario(
        tmp_path,
        ScenarioSpec(
            missions=(
                mission("Agent_0", start=(20.0, lane_y(0), 0.0)),
                mission("Agent_1", start=(20.0, lane_y(1), 0.0), goal=(120.0, lane_y(1))),
            ),
        ),
    )

    def policy(obs):
        x, y, _ = obs["ego_vehicle_state"]["position"]
        if obs["ego_vehicle_state"]["id"] == "Agent_0":
            return [x + 1.0, y - 0.5, -0.5, 0.1]
        return [x + 1.0, y, 0.0, 0.1]

    r = run(folder, policy)
    ended = next(i for i, obs in enumerate(r.agent.seen) if obs.get("Agent_0", {}).get("done"))
    last = r.agent.seen[ended]["Agent_0"]
    assert last["events"]["off_road"] and last["done"]
    assert not r.agent.seen[ended]["Agent_1"]["done"]
    assert all(not obs["Agent_0"]["done"] for obs in r.agent.seen[:ended])
    for obs in r.agent.seen[ended + 1 :]:
        assert "Agent_0" not in obs
        assert "Agent_0" not in [n["id"] for n in obs["Agent_1"]["neighborhood_vehicle_states"]]
    assert len(r.agent.seen) > ended + 1
    assert {o.id: o.reason for o in r.result.agents}["Agent_0"] is DoneReason.off_road


FORWARD = {
    ActionSpace.TargetPose: lambda o: drive_straight(8.0)(o),
    ActionSpace.RelativeTargetPose: lambda o: [0.8, 0.0, 0.0],
    ActionSpace.Continuous: lambda o: [0.5, 0.0, 0.0],
    ActionSpace.LaneWithContinuousSpeed: lambda o: [8.0, 0.0],
}


@pytest.mark.parametrize("space", list(ActionSpace))
def test_every_action_space_drives_forward_with_serialisable_observations(tmp_path, run, space):
    assert set(FORWARD) == set(ActionSpace)
    folder = make_scenario(tmp_path, ScenarioSpec(max_episode_steps=30))
    r = run(folder, FORWARD[space], space)
    assert r.outcome.reason is DoneReason.max_episode_steps and r.outcome.steps == 30
    rec = r.record
    assert rec["x"][0, -1] > 20.0 + 5.0
    assert abs(rec["lane_offset"][0, -1]) < 0.3 and not rec["ev_wrong_way"].any()
    json.dumps(r.agent.seen[-1])  # crosses a process boundary as JSON


@pytest.mark.parametrize(
    ("bad", "rule"),
    [
        # Finite but huge: became a NaN pose inside the simulator, i.e. an uncharged
        # simulator_error the agent could choose.
        ([1.7e308, 1.7e308, 0.0, 0.1], "range"),
        # A JSON integer beyond float range: an uncaught OverflowError.
        ([10**400, 0.0, 0.0, 0.1], "not-numbers"),
        ([float("inf"), 0.0, 0.0, 0.1], "finite"),
        ([1.0, 2.0, 3.0], "shape"),
    ],
)
def test_a_bad_action_is_the_agents_invalid_action_naming_the_rule(tmp_path, run, bad, rule):
    folder = make_scenario(tmp_path, ScenarioSpec())

    def policy(obs):
        return bad if obs["step_count"] == 4 else drive_straight(10.0)(obs)

    r = run(folder, policy)
    assert r.outcome.reason is DoneReason.invalid_action and r.outcome.steps == 4
    assert f"[rule: {rule}]" in r.result.detail and "Agent_0" in r.result.detail
    assert list(r.record["done_reason"]) == ["invalid_action"]


def test_an_action_for_an_unknown_or_missing_agent_id_is_named(tmp_path, run):
    folder = make_scenario(tmp_path, ScenarioSpec())

    class Extra(ScriptedAgent):
        def act(self, obs):
            return {**super().act(obs), "Agent_9": [0.0, 0.0, 0.0, 0.1]}

    from sim.episode import run_episode
    from sim.interface import AgentInterface

    result = run_episode(
        folder, Extra(drive_straight(10.0)), AgentInterface(), record_path=tmp_path / "r.npz"
    )
    assert result.agents[0].reason is DoneReason.invalid_action
    assert "unknown agent id 'Agent_9'" in result.detail and "unknown-agent-id" in result.detail

    honest = ScriptedAgent(drive_straight(10.0))
    missing = run_episode(folder, honest, AgentInterface(), record_path=tmp_path / "m.npz")
    assert missing.agents[0].reason is DoneReason.reached_goal  # the honest run is unaffected

    class Silent(ScriptedAgent):
        def act(self, obs):
            super().act(obs)
            return {}

    silent = run_episode(
        folder, Silent(drive_straight(10.0)), AgentInterface(), record_path=tmp_path / "s.npz"
    )
    assert silent.agents[0].reason is DoneReason.invalid_action
    assert "no action for agent id 'Agent_0' [rule: missing-agent-id]" in silent.detail


def test_an_agents_exception_ends_every_agent_and_reset_names_them_all(tmp_path):
    """The agent raises at step 5 while driving two mission vehicles: both end with agent_error
    at that step (one rule, docs/protocol.md "An exception in act"). An agent that takes agent
    ids is reset with every mission's id."""
    from pathlib import Path

    from sim.episode import run_episode
    from sim.interface import AgentInterface
    from tests.sim.agents import ScriptedAgent

    folder = make_scenario(
        tmp_path,
        ScenarioSpec(
            missions=(
                mission("Agent_0", start=(20.0, lane_y(0), 0.0)),
                mission("Agent_1", start=(20.0, lane_y(1), 0.0), goal=(120.0, lane_y(1))),
            ),
        ),
    )

    class FailsAtStep5(ScriptedAgent):
        takes_agent_ids = True

        def reset(self, agent_ids):
            super().reset()
            self.agent_ids = agent_ids

        def act(self, obs):
            actions = super().act(obs)
            if len(self.seen) == 5:
                raise ValueError("bad input for Agent_0")
            return actions

    agent = FailsAtStep5(drive_straight(10.0))
    result = run_episode(
        folder, agent, AgentInterface(), record_path=Path(tmp_path) / "records" / "r.npz"
    )
    assert agent.agent_ids == ["Agent_0", "Agent_1"]
    assert [(o.reason, o.steps) for o in result.agents] == [(DoneReason.agent_error, 4)] * 2
    assert "ValueError: bad input for Agent_0" in result.detail
