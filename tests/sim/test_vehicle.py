import math

import numpy as np
import pytest

from sim.interface import ACTION_LENGTH, ActionSpace
from sim.vehicle import (
    DECODERS,
    LIMITS,
    MAX_ACTION_MAGNITUDE,
    ControlContext,
    InvalidAction,
    Pose,
    bicycle_step,
    check_action,
    parse_action,
)


def ctx(road=None) -> ControlContext:
    return ControlContext(dt=0.1, length=4.5, road=road, route=())


def test_bicycle_straight_acceleration_and_speed_limits():
    pose = Pose(0.0, 0.0, 0.0, 10.0)
    after = bicycle_step(pose, 2.0, 0.0, 0.1, 4.5, 28.0)
    assert after.speed == pytest.approx(10.2)
    assert after.x == pytest.approx(0.1 * (10.0 + 10.2) / 2)
    assert after.y == 0.0 and after.heading == 0.0
    # Braking never reverses; speed saturates at the maximum.
    assert bicycle_step(Pose(0, 0, 0, 0.3), -8.0, 0.0, 0.1, 4.5, 28.0).speed == 0.0
    assert bicycle_step(Pose(0, 0, 0, 27.9), 3.0, 0.0, 0.1, 4.5, 28.0).speed == 28.0


def test_bicycle_turns_left_on_a_circle():
    pose = Pose(0.0, 0.0, 0.0, 5.0)
    for _ in range(100):
        pose = bicycle_step(pose, 0.0, 0.3, 0.1, 4.5, 28.0)
    assert pose.y > 0  # positive steering turns counter-clockwise
    # Radius of the centre of gravity path: lr / sin(beta), beta = atan(tan(delta) / 2).
    lr = 0.6 * 4.5 / 2
    radius = lr / math.sin(math.atan(0.5 * math.tan(0.3)))
    expected_turn = 5.0 * 10.0 / radius
    assert math.remainder(pose.heading - expected_turn, 2 * math.pi) == pytest.approx(0, abs=1e-9)


def test_target_pose_displacement_capped_at_2_8_m_per_step():
    pose = Pose(0.0, 0.0, 0.0, 0.0)
    after = DECODERS[ActionSpace.TargetPose](np.array([30.0, 40.0, 1.0, 0.1]), pose, ctx())
    assert math.hypot(after.x, after.y) == pytest.approx(2.8)
    assert (after.x, after.y) == pytest.approx((2.8 * 0.6, 2.8 * 0.8))
    assert after.speed == pytest.approx(28.0) and after.heading == 1.0
    small = DECODERS[ActionSpace.TargetPose](np.array([1.0, 0.0, 0.0, 0.1]), pose, ctx())
    assert (small.x, small.speed) == pytest.approx((1.0, 10.0))


def test_relative_target_pose_is_in_the_ego_frame_and_capped():
    pose = Pose(10.0, 5.0, math.pi / 2, 0.0)
    after = DECODERS[ActionSpace.RelativeTargetPose](np.array([1.0, 0.5, 0.1]), pose, ctx())
    assert (after.x, after.y) == pytest.approx((9.5, 6.0))
    assert after.heading == pytest.approx(math.pi / 2 + 0.1)
    far = DECODERS[ActionSpace.RelativeTargetPose](np.array([10.0, 0.0, 0.0]), pose, ctx())
    assert (far.x, far.y) == pytest.approx((10.0, 5.0 + LIMITS.max_speed * 0.1))


def test_continuous_clips_out_of_range_values():
    pose = Pose(0.0, 0.0, 0.0, 10.0)
    clipped = DECODERS[ActionSpace.Continuous](np.array([5.0, -3.0, 9.0]), pose, ctx())
    exact = DECODERS[ActionSpace.Continuous](np.array([1.0, 0.0, 1.0]), pose, ctx())
    assert clipped == exact
    assert exact.speed == pytest.approx(10.0 + LIMITS.max_acceleration * 0.1)
    assert exact.steering == pytest.approx(LIMITS.max_steering)


@pytest.mark.parametrize("space", list(ActionSpace))
def test_invalid_actions_are_detected_for_every_space(space):
    n = ACTION_LENGTH[space]
    assert parse_action([0.5] * n, space) is not None
    assert parse_action([0.5] * (n + 1), space) is None
    assert parse_action([0.5] * (n - 1), space) is None
    assert parse_action([float("nan")] + [0.0] * (n - 1), space) is None
    assert parse_action([float("inf")] + [0.0] * (n - 1), space) is None
    assert parse_action("fast", space) is None
    assert parse_action(None, space) is None


@pytest.mark.parametrize(
    ("raw", "rule", "quoted"),
    [
        ([1.7e308, 1.7e308, 0.0, 0.1], "range", "1.7e+308"),
        ([10**400, 0.0, 0.0, 0.1], "not-numbers", "1000000000"),
        ([float("nan"), 0.0, 0.0, 0.1], "finite", "nan"),
        ([0.0, float("-inf"), 0.0, 0.1], "finite", "-inf"),
        ([1.0, 2.0], "shape", "[1.0, 2.0]"),
        ([[1.0, 2.0, 3.0, 4.0]], "shape", "[[1.0"),
        ("fast", "not-numbers", "'fast'"),
    ],
)
def test_invalid_action_names_the_rule_and_the_value(raw, rule, quoted):
    with pytest.raises(InvalidAction) as caught:
        check_action(raw, ActionSpace.TargetPose)
    assert caught.value.rule == rule
    message = str(caught.value)
    assert quoted in message and f"[rule: {rule}]" in message
    assert len(message) < 300  # a huge value is quoted, not copied


def test_every_finite_action_within_the_bound_decodes_to_a_finite_pose():
    """The bound is what keeps huge-but-finite values from becoming NaN in the geometry."""
    pose = Pose(10.0, 5.0, 0.3, 12.0)
    edge = MAX_ACTION_MAGNITUDE
    for space in (ActionSpace.TargetPose, ActionSpace.RelativeTargetPose, ActionSpace.Continuous):
        for sign in (1.0, -1.0):
            action = check_action([sign * edge] * ACTION_LENGTH[space], space)
            after = DECODERS[space](action, pose, ctx())
            assert all(math.isfinite(v) for v in (after.x, after.y, after.heading, after.speed))
    with pytest.raises(InvalidAction):
        check_action([edge * 1.0001, 0.0, 0.0, 0.1], ActionSpace.TargetPose)
