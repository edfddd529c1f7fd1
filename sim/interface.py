"""The agent interface options a submission chooses in ``agent.yaml``.

The simulator owns these because it is what honours them (action decoding, observation contents);
the submission intake validates ``agent.yaml`` into :class:`AgentInterface`.
"""

from __future__ import annotations

from enum import StrEnum
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator


class ActionSpace(StrEnum):
    TargetPose = "TargetPose"  # [x, y, heading, dt]
    RelativeTargetPose = "RelativeTargetPose"  # [dx, dy, dheading] in the ego frame
    Continuous = "Continuous"  # [throttle 0..1, brake 0..1, steering -1..1]
    LaneWithContinuousSpeed = "LaneWithContinuousSpeed"  # [target_speed m/s, lane_change -1|0|1]


ACTION_LENGTH: dict[ActionSpace, int] = {
    ActionSpace.TargetPose: 4,
    ActionSpace.RelativeTargetPose: 3,
    ActionSpace.Continuous: 3,
    ActionSpace.LaneWithContinuousSpeed: 2,
}


class ObservationFormat(StrEnum):
    """How the in-sandbox runner hands observations to the policy (the simulator is unaffected)."""

    native = "native"  # plain dicts and lists, our heading frame (0 = +x east)
    # numpy arrays of fixed shapes, the Gymnasium space of learn/: sim/observation_arrays.py
    arrays = "arrays"
    smarts2022 = (
        "smarts2022"  # SMARTS attribute objects, numpy, 0 = +y north: docs/smarts-compat.md
    )


class AgentInterface(BaseModel):
    """Contents of ``agent.yaml``; every key is optional, a misspelt key is an error."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    action_space: ActionSpace = ActionSpace.TargetPose
    observation_format: ObservationFormat = ObservationFormat.native
    observation_radius: float = Field(default=100.0, gt=0, le=200)  # [m]
    max_waypoint_paths: int = Field(default=4, ge=1, le=4)
    waypoints_per_path: int = Field(default=50, ge=1, le=50)
    # Optional ego-centred rasters: `img_pixels` square covering `img_meters` across.
    drivable_area_grid_map: bool = False
    occupancy_grid_map: bool = False
    top_down_rgb: bool = False
    img_pixels: int = Field(default=256, ge=16, le=512)
    img_meters: float = Field(default=64.0, gt=0, le=200)
    # Neighbour slots of the fixed-shape observation (`observation_format: arrays`, the learn
    # environments): the nearest are kept. The native format lists every one in the radius.
    max_neighbours: int = Field(default=16, ge=1, le=64)
    # SMARTS's lidar (300 rays of 20 m) and road waypoints (every lane of the ego's road, 20 m
    # behind to 20 m ahead): docs/agent-interface.md. Not in the fixed-shape arrays format.
    lidar_point_cloud: bool = False
    road_waypoints: bool = False
    # smarts2022 only: the names the kit's FormatObs gives its keys, SMARTS comp-1's (`ego`,
    # `rgb`, `waypoints`, ...) or later SMARTS's (`ego_vehicle_state`, ...): docs/smarts-compat.md.
    format_obs_keys: Literal["comp-1", "later"] = "comp-1"

    @model_validator(mode="after")
    def _arrays_have_fixed_parts_only(self) -> AgentInterface:
        if self.observation_format is ObservationFormat.arrays and (
            self.lidar_point_cloud or self.road_waypoints
        ):
            raise ValueError(
                "lidar_point_cloud and road_waypoints are not part of observation_format: "
                "arrays (use native or smarts2022)"
            )
        return self
