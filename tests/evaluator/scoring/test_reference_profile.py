"""The ``driving-smarts-2022-reference`` profile: the competition code's formulas (issue 10), each
checked on hand-built records against the paper's profile."""

from __future__ import annotations

import json

import numpy as np
import pytest

from arena_command import app
from evaluator.scoring import aggregate, load_profile, load_record, score_episode
from evaluator.scoring.registry import get_term
from tests.cli_runner import CliRunner
from tests.evaluator.runner.test_cli import results  # noqa: F401  (fixture: a results folder)
from tests.evaluator.scoring.builders import DT, AgentSpec, drive, track, write_record

PAPER = load_profile("driving-smarts-2022")
REFERENCE = load_profile("driving-smarts-2022-reference")


def scored(tmp_path, scenario_id, agents, profile):
    path = write_record(tmp_path / f"{scenario_id}.npz", scenario_id, agents)
    return score_episode(load_record(path), profile)


def test_paper_profile_stays_the_default():
    from arena.config import Settings

    assert load_profile().name == PAPER.name == Settings().evaluation.scoring_profile


def test_jerk_is_the_squared_change_of_acceleration_not_divided_by_dt():
    # Speed 10 m/s, then accelerating at 2 m/s^2 from row 5 on: one change of acceleration.
    speed = np.where(np.arange(10) < 5, 10.0, 10.0 + 2.0 * DT * (np.arange(10) - 4))
    rows = drive(10, speed=speed, vx=speed, vy=0.0)
    reference = get_term("jerk_squared_change")(track(rows), REFERENCE)
    paper = get_term("jerk")(track(rows), PAPER)
    assert reference.sum() == pytest.approx(2.0**2)  # |delta a|^2, once
    assert paper.sum() == pytest.approx(2.0 / DT)  # |delta a| / dt, once


def test_jerk_adds_the_squared_change_of_angular_acceleration():
    # Heading starts turning at 0.5 rad/s at row 4: yaw rate steps, angular acceleration spikes
    # (5 rad/s^2) for one step, so it changes twice by 5 rad/s^2.
    heading = np.where(np.arange(10) < 4, 0.0, 0.5 * DT * (np.arange(10) - 3))
    rows = drive(10, vx=10.0, vy=0.0)
    rows["heading"] = heading
    values = get_term("jerk_squared_change")(track(rows), REFERENCE)
    assert values.sum() == pytest.approx(2 * (0.5 / DT) ** 2)


def test_lane_offset_is_divided_by_half_the_lane_width():
    rows = drive(5, lane_offset=0.8, lane_width=3.2)
    assert get_term("lc_off_half_width")(track(rows), REFERENCE) == pytest.approx(0.25)
    assert get_term("lc_off")(track(rows), PAPER) == pytest.approx(0.0625)


def ahead_of(rows: dict[str, np.ndarray], gaps: dict[int, float]) -> np.ndarray:
    """Neighbour centres ``(n, 1, 2)``: one vehicle ``gaps[row]`` metres straight ahead of the
    ego at each listed row, none elsewhere."""
    nbr = np.full((len(rows["x"]), 1, 2), np.nan)
    for row, gap in gaps.items():
        nbr[row] = [[rows["x"][row] + gap, rows["y"][row]]]
    return nbr


def test_obstacle_term_is_the_running_mean_at_steps_with_a_vehicle_ahead_else_0():
    rows = drive(6, speed=10.0)
    t = track(rows, ahead_of(rows, {1: 10.0, 3: 20.0}))
    running = get_term("distance_obs_running_mean")(t, REFERENCE)
    per_step = get_term("distance_obs")(t, PAPER)
    assert per_step[[1, 3]] == pytest.approx([np.exp(-0.5), np.exp(-1.0)])
    assert running[1] == pytest.approx(per_step[1])
    assert running[3] == pytest.approx(per_step[[1, 3]].mean())  # mean over rows 1 and 3 only
    assert running[[0, 2, 4, 5]] == pytest.approx(0.0)


def test_an_agent_whose_last_step_has_nothing_ahead_scores_0_on_the_obstacle_term(tmp_path):
    """The spec's second profile: "that running mean if its last row had an obstacle, else 0".
    Two hand-made agents see the same vehicles ahead at rows 1 and 3; one also at its last row."""
    rows = drive(6, speed=10.0)
    clear_at_end = AgentSpec(rows, nbr_xy=ahead_of(rows, {1: 10.0, 3: 20.0}))
    blocked_at_end = AgentSpec(rows, nbr_xy=ahead_of(rows, {1: 10.0, 3: 20.0, 5: 10.0}))
    clear = scored(tmp_path, "clear", [clear_at_end], REFERENCE)
    blocked = scored(tmp_path, "blocked", [blocked_at_end], REFERENCE)
    # A straight, centred, steady drive within the limit: the obstacle term is all of humanness.
    assert clear.term_sums["distance_obs_running_mean"] == 0.0
    assert clear.humanness == 0.0
    closeness = [np.exp(-0.5), np.exp(-1.0), np.exp(-0.5)]
    assert blocked.term_sums["distance_obs_running_mean"] == pytest.approx(np.mean(closeness))
    assert blocked.humanness == pytest.approx(np.mean(closeness))


def test_humanness_is_averaged_per_agent_episode(tmp_path):
    """A long smooth episode and a short weaving one: per agent-step the long one dominates,
    per agent-episode both weigh the same."""
    long = scored(tmp_path, "a", [AgentSpec(drive(300))], REFERENCE)
    short = scored(tmp_path, "b", [AgentSpec(drive(10, lane_offset=0.8))], REFERENCE)
    metrics = aggregate([long, short])
    assert metrics.humanness == pytest.approx((0.0 + 0.25) / 2)
    paper = aggregate(
        [
            scored(tmp_path, "a", [AgentSpec(drive(300))], PAPER),
            scored(tmp_path, "b", [AgentSpec(drive(10, lane_offset=0.8))], PAPER),
        ]
    )
    assert paper.humanness == pytest.approx(10 * 0.0625 / 310)


def test_time_adds_the_goal_l1_distance_summed_over_agents(tmp_path):
    # The builder puts each goal at the agent's last row; move it 3 m east and 4 m north.
    agents = [AgentSpec(drive(50), reason="collision"), AgentSpec(drive(60), reason="off_road")]
    path = write_record(tmp_path / "c.npz", "c", agents)
    with np.load(path) as data:
        arrays = {k: data[k] for k in data.files}
    arrays["goal_x"] = arrays["goal_x"] + 3.0
    arrays["goal_y"] = arrays["goal_y"] + 4.0
    np.savez_compressed(path, **arrays)
    record = load_record(path)
    assert score_episode(record, REFERENCE).time == pytest.approx(800 + 2 * (3.0 + 4.0))
    assert score_episode(record, PAPER).time == 800


def test_arena_score_rescores_stored_records_with_the_reference_profile(results):  # noqa: F811
    paper = CliRunner().invoke(app, ["score", str(results), "--json"])
    reference = CliRunner().invoke(
        app, ["score", str(results), "--json", "--profile", "driving-smarts-2022-reference"]
    )
    assert paper.exit_code == 0 and reference.exit_code == 0, reference.output
    paper_m = json.loads(paper.stdout)["metrics"]
    ref = json.loads(reference.stdout)
    assert ref["profile"]["name"] == "driving-smarts-2022-reference"
    assert ref["metrics"]["completion"] == paper_m["completion"]
    # Scenario a: 300 steps at 0.5 m off-centre in a 3.2 m lane.
    assert ref["metrics"]["humanness"] == pytest.approx((0.5 / 1.6) ** 2 / 2)
    assert paper_m["humanness"] == pytest.approx(300 * (0.5 / 3.2) ** 2 / 420)
