"""Events and done reasons from our own geometry, with real SUMO traffic."""

import math

import numpy as np

from arena.outcome import DoneReason
from tests.sim.agents import drive_straight, stand_still
from tests.sim.builders import (
    ScenarioSpec,
    lane_y,
    make_scenario,
    mission,
    straight_road,
    vehicle_xml,
)


def one_lane(folder):
    return straight_road(folder, lanes=1)


def test_side_swipe_is_a_collision(tmp_path, run):
    # The ego drives level with a background car on the next lane and drifts into its side:
    # no front/back overlap at all, which SUMO's own check would miss.
    folder = make_scenario(
        tmp_path,
        ScenarioSpec(
            missions=(mission(start=(52.25, lane_y(1), 0.0), speed=13.89),),
            vehicles=[vehicle_xml("side", 54.5, 0, 13.89, vtype="steady")],
        ),
    )

    def drift_right(obs):
        x, y, _ = obs["ego_vehicle_state"]["position"]
        return [x + 1.389, y - 0.1, 0.0, 0.1]

    r = run(folder, drift_right)
    assert r.outcome.reason is DoneReason.collision
    rec = r.record
    hit = int(np.flatnonzero(rec["ev_collision"][0])[0])
    assert hit == r.outcome.steps - 1
    other = list(rec["nbr_id"][0, hit]).index("side")
    dx = rec["nbr_x"][0, hit, other] - rec["x"][0, hit]
    dy = rec["y"][0, hit] - rec["nbr_y"][0, hit, other]
    assert abs(dx) < 1.0  # side by side
    assert 1.6 < dy <= 1.8  # within one body width laterally
    assert not rec["ev_collision"][0, :hit].any()


def test_background_vehicle_that_cannot_stop_rear_ends_a_stopped_ego(tmp_path, run):
    folder = make_scenario(
        tmp_path,
        ScenarioSpec(
            missions=(mission(start=(200.0, lane_y(0, 1), 0.0), goal=(380.0, lane_y(0, 1))),),
            vehicles=[vehicle_xml("reckless", 120.0, 0, 13.0, vtype="reckless")],
            net=one_lane,
        ),
    )
    r = run(folder, stand_still)
    assert r.outcome.reason is DoneReason.collision
    step = r.outcome.steps - 1
    ids = list(r.record["nbr_id"][0, step])
    assert "reckless" in ids
    assert r.record["nbr_speed"][0, step, ids.index("reckless")] > 5.0  # it did not yield


def test_reactive_follower_brakes_behind_a_slow_ego(tmp_path, run):
    folder = make_scenario(
        tmp_path,
        ScenarioSpec(
            missions=(
                mission(start=(150.0, lane_y(0, 1), 0.0), goal=(390.0, lane_y(0, 1)), speed=4.0),
            ),
            vehicles=[vehicle_xml("follower", 60.0, 0, 13.89, vtype="steady")],
            net=one_lane,
            max_episode_steps=300,
        ),
    )
    r = run(folder, drive_straight(4.0))
    assert r.outcome.reason is DoneReason.max_episode_steps
    assert not r.record["ev_collision"].any()
    rec = r.record
    slot = list(rec["nbr_id"][0, -1]).index("follower")
    assert rec["nbr_x"][0, -1, slot] < rec["x"][0, -1] - 4.5  # still behind the ego
    assert abs(rec["nbr_speed"][0, -1, slot] - 4.0) < 0.5  # adapted to the ego's speed
    first = list(rec["nbr_id"][0, 0]).index("follower")
    assert rec["nbr_speed"][0, 0, first] > 12.0  # it came in fast


def test_replay_vehicles_ignore_the_ego(tmp_path, run):
    y = lane_y(1)
    rows = ["vehicle_id,time,x,y,heading,speed,length,width"]
    rows += [f"rec,{k / 10:.1f},{100 + k:.3f},{y:.3f},0.00000,10.000,4.50,1.80" for k in range(200)]
    folder = make_scenario(
        tmp_path,
        ScenarioSpec(
            missions=(mission(start=(160.0, y, 0.0)),), trajectories="\n".join(rows) + "\n"
        ),
    )
    r = run(folder, stand_still)
    rec = r.record
    steps = rec["step"][0, : r.outcome.steps]
    slot = [list(ids).index("rec") for ids in rec["nbr_id"][0, : r.outcome.steps]]
    xs = rec["nbr_x"][0, np.arange(len(slot)), slot]
    np.testing.assert_allclose(xs, 100.0 + steps, atol=1e-6)  # exactly as recorded
    assert r.outcome.reason is DoneReason.collision
    # Contact when the gap between centres is below one length.
    assert 100.0 + steps[-1] >= 160.0 - 4.5


def test_leaving_the_road_is_off_road(tmp_path, run):
    folder = make_scenario(
        tmp_path, ScenarioSpec(missions=(mission(start=(50.0, lane_y(0), 0.0)),))
    )

    def to_the_right(obs):
        x, y, _ = obs["ego_vehicle_state"]["position"]
        return [x + 0.5, y - 0.5, -math.pi / 4, 0.1]

    r = run(folder, to_the_right)
    assert r.outcome.reason is DoneReason.off_road
    last = r.outcome.steps - 1
    assert r.record["ev_off_road"][0, last] and not r.record["ev_off_road"][0, :last].any()
    assert r.record["y"][0, last] < lane_y(0) - 1.6


def test_driving_against_the_lane_direction_is_wrong_way(tmp_path, run):
    folder = make_scenario(
        tmp_path,
        ScenarioSpec(
            missions=(mission(start=(50.0, 1.6, 0.0), goal=(90.0, 1.6), route=("W",)),),
        ),
    )
    r = run(folder, drive_straight(5.0))
    rec = r.record
    n = r.outcome.steps
    assert r.outcome.reason is DoneReason.reached_goal
    assert rec["ev_wrong_way"][0, :n].all()
    assert set(rec["lane_id"][0, :n]) == {"W_0"}
    assert np.allclose(np.abs(rec["lane_heading"][0, :n]), math.pi)
    assert r.agent.seen[-1]["Agent_0"]["events"]["wrong_way"] is True


def test_reaching_the_goal(tmp_path, run):
    folder = make_scenario(
        tmp_path,
        ScenarioSpec(missions=(mission(start=(20.0, lane_y(1), 0.0), goal=(60.0, lane_y(1))),)),
    )
    r = run(folder, drive_straight(10.0))
    assert r.outcome.reason is DoneReason.reached_goal and r.outcome.reached_goal
    # 1 m per step from x = 20: within 2 m of x = 60 after 38 steps.
    assert r.outcome.steps == 38 == r.outcome.done_step == r.result.steps
    rec = r.record
    assert rec["ev_reached_goal"][0, 37] and not rec["ev_reached_goal"][0, :37].any()
    assert not rec["ev_wrong_way"].any() and not rec["ev_off_route"].any()
    np.testing.assert_allclose(rec["vx"][0, :38], 10.0)
    np.testing.assert_allclose(rec["lane_offset"][0, :38], 0.0, atol=1e-9)
    assert rec["speed_limit"][0, 0] == np.float64(13.89)


def test_replay_vehicles_near_the_ego_turn_reactive_inside_the_bubble(tmp_path, run):
    # The same recorded vehicle as above, now with a reactive bubble: once within 30 m of the
    # stopped ego it is handed to SUMO, which brakes instead of driving through.
    y = lane_y(0, 1)  # one lane: the reactive vehicle cannot pass, it must brake
    rows = ["vehicle_id,time,x,y,heading,speed,length,width"]
    rows += [f"rec,{k / 10:.1f},{100 + k:.3f},{y:.3f},0.00000,10.000,4.50,1.80" for k in range(200)]
    folder = make_scenario(
        tmp_path,
        ScenarioSpec(
            missions=(mission(start=(160.0, y, 0.0), goal=(380.0, y)),),
            trajectories="\n".join(rows) + "\n",
            bubble_radius=30.0,
            net=one_lane,
            max_episode_steps=150,
        ),
    )
    r = run(folder, stand_still)
    assert r.outcome.reason is DoneReason.max_episode_steps
    rec = r.record
    slot = list(rec["nbr_id"][0, -1]).index("rec")
    assert 150.0 < rec["nbr_x"][0, -1, slot] < 160.0 - 4.5  # stopped behind the ego
    assert rec["nbr_speed"][0, -1, slot] < 0.5
    first = list(rec["nbr_id"][0, 0]).index("rec")
    assert rec["nbr_x"][0, 0, first] == 101.0  # replayed exactly while outside the bubble
