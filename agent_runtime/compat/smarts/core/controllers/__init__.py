"""SMARTS's action spaces (``smarts.core.controllers.ActionSpaceType``)."""

from enum import Enum

METER_PER_SECOND_TO_KM_PER_HR = 3.6


class ActionSpaceType(Enum):
    Continuous = 0  # [throttle 0..1, brake 0..1, steering -1..1]
    Lane = 1  # "keep_lane", "slow_down", "change_lane_left", "change_lane_right"
    ActuatorDynamic = 2
    LaneWithContinuousSpeed = 3  # [target speed m/s, lane change -1|0|1]
    TargetPose = 4  # [x, y, heading, dt]
    Trajectory = 5
    MultiTargetPose = 6
    MPC = 7
    TrajectoryWithTime = 8
    Direct = 9
    Empty = 10
    RelativeTargetPose = 11  # [dx, dy, dheading] in the ego frame
