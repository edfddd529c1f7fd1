import numpy as np
import pytest

from evaluator.scoring import load_profile
from evaluator.scoring.registry import get_term, term_names
from evaluator.scoring.terms import distance_obs, jerk, lc_off, speeding, wrong_way
from tests.evaluator.scoring.builders import DT, drive, track

PROFILE = load_profile()


def one_neighbour(rows, dx: float, dy: float) -> np.ndarray:
    """A neighbour at a fixed offset (dx, dy) [m] from the ego centre on every row."""
    return np.stack([rows["x"] + dx, rows["y"] + dy], axis=-1)[:, None, :]


@pytest.mark.parametrize("name", term_names())
def test_every_term_gives_one_finite_value_per_driven_row(name):
    rows = drive(5, speed=12.0, lane_offset=0.4)
    values = get_term(name)(track(rows, one_neighbour(rows, 10.0, 0.0)), PROFILE)
    assert values.shape == (5,)
    assert np.isfinite(values).all()
    assert get_term(name)(track(drive(0)), PROFILE).shape == (0,)


class TestDistanceObs:
    def test_vehicle_ahead_within_reach_counts_by_distance(self):
        rows = drive(3, speed=10.0)  # reach = 3 s x 10 m/s = 30 m
        values = distance_obs(track(rows, one_neighbour(rows, 20.0, 0.0)), PROFILE)
        np.testing.assert_allclose(values, np.exp(-0.05 * 20.0))

    @pytest.mark.parametrize(
        ("dx", "dy", "counted"),
        [
            (20.0 * np.cos(np.deg2rad(35)), 20.0 * np.sin(np.deg2rad(35)), True),
            (20.0 * np.cos(np.deg2rad(-35)), 20.0 * np.sin(np.deg2rad(-35)), True),
            (20.0 * np.cos(np.deg2rad(45)), 20.0 * np.sin(np.deg2rad(45)), False),
            (0.0, 5.0, False),  # beside
            (-10.0, 0.0, False),  # behind
            (31.0, 0.0, False),  # ahead but beyond 3 s x speed
        ],
    )
    def test_only_vehicles_ahead_within_40_degrees_and_3_seconds(self, dx, dy, counted):
        rows = drive(2, speed=10.0)
        values = distance_obs(track(rows, one_neighbour(rows, dx, dy)), PROFILE)
        expected = np.exp(-0.05 * np.hypot(dx, dy)) if counted else 0.0
        np.testing.assert_allclose(values, expected)

    def test_ahead_is_relative_to_the_ego_heading(self):
        rows = drive(2, speed=10.0, heading=np.pi / 2)  # driving north
        north = distance_obs(track(rows, one_neighbour(rows, 0.0, 10.0)), PROFILE)
        east = distance_obs(track(rows, one_neighbour(rows, 10.0, 0.0)), PROFILE)
        np.testing.assert_allclose(north, np.exp(-0.5))
        np.testing.assert_allclose(east, 0.0)

    def test_closest_of_several_vehicles_ahead_wins(self):
        rows = drive(1, speed=10.0)
        xy = np.array([[[rows["x"][0] + 25.0, 0.0], [rows["x"][0] + 8.0, 0.0], [np.nan, np.nan]]])
        np.testing.assert_allclose(distance_obs(track(rows, xy), PROFILE), np.exp(-0.05 * 8.0))

    def test_stationary_ego_sees_nothing(self):
        rows = drive(3, speed=0.0)
        values = distance_obs(track(rows, one_neighbour(rows, 0.0, 0.0)), PROFILE)
        np.testing.assert_array_equal(values, 0.0)


class TestJerk:
    def test_constant_velocity_has_no_jerk(self):
        np.testing.assert_allclose(jerk(track(drive(10, speed=7.0)), PROFILE), 0.0)

    def test_first_two_steps_are_zero_and_then_change_of_acceleration_over_dt(self):
        # speeds 10, 20, 20, 21: accelerations (rows 1..3) 100, 0, 10 m/s^2
        rows = drive(4, speed=0.0, vx=np.array([10.0, 20.0, 20.0, 21.0]), vy=0.0)
        values = jerk(track(rows), PROFILE)
        np.testing.assert_allclose(values, [0.0, 0.0, 100.0 / DT, 10.0 / DT])

    def test_uses_the_velocity_vector_not_only_speed(self):
        # same speed, heading turns 90 degrees in one step then holds
        rows = drive(3, speed=10.0, vx=np.array([10.0, 10.0, 0.0]), vy=np.array([0.0, 0.0, 10.0]))
        accel_change = np.hypot(-10.0, 10.0) / DT  # [m/s^2]
        np.testing.assert_allclose(jerk(track(rows), PROFILE), [0.0, 0.0, accel_change / DT])


def test_lc_off_is_squared_offset_over_lane_width():
    rows = drive(3, lane_offset=np.array([0.0, -0.8, 1.6]), lane_width=3.2)
    np.testing.assert_allclose(lc_off(track(rows), PROFILE), [0.0, 0.0625, 0.25])


class TestSpeeding:
    def test_at_or_under_the_limit_is_free(self):
        rows = drive(2, speed=np.array([13.89, 5.0]), speed_limit=13.89)
        np.testing.assert_array_equal(speeding(track(rows), PROFILE), 0.0)

    def test_over_the_limit_scales_with_half_the_limit_and_saturates_at_one(self):
        rows = drive(3, speed=np.array([11.0, 15.0, 40.0]), speed_limit=10.0)
        np.testing.assert_allclose(speeding(track(rows), PROFILE), [0.2, 1.0, 1.0])


class TestWrongWay:
    def test_against_the_lane_outside_a_junction_counts(self):
        rows = drive(2, heading=np.pi, lane_heading=0.0)
        np.testing.assert_array_equal(wrong_way(track(rows), PROFILE), 1.0)

    def test_against_the_lane_inside_a_junction_is_not_checked(self):
        rows = drive(2, heading=np.pi, lane_heading=0.0, in_junction=True)
        np.testing.assert_array_equal(wrong_way(track(rows), PROFILE), 0.0)

    @pytest.mark.parametrize(
        ("heading", "lane_heading", "expected"),
        [
            (np.deg2rad(89.0), 0.0, 0.0),
            (np.deg2rad(91.0), 0.0, 1.0),
            (np.pi - 0.05, -np.pi + 0.05, 0.0),  # same direction across the +-pi seam
            (-np.pi / 2 - 0.1, np.pi / 2 - 0.05, 1.0),
        ],
    )
    def test_threshold_is_90_degrees_with_angles_wrapped(self, heading, lane_heading, expected):
        rows = drive(1, heading=heading, lane_heading=lane_heading)
        np.testing.assert_array_equal(wrong_way(track(rows), PROFILE), expected)
