import math

import numpy as np
import pytest

from sim.interface import ACTION_LENGTH, ActionSpace
from sim.vehicle import DECODERS, LIMITS, ControlContext, Pose, bicycle_step, parse_action


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
