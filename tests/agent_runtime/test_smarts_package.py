"""The ``smarts`` and ``gym`` compatibility packages (``agent_runtime/compat/``) behave as SMARTS's
documentation says, and the kit's wrappers accept what the adapter builds."""

from __future__ import annotations

import math

import numpy as np
import pytest
from smarts.core.controllers import ActionSpaceType
from smarts.core.coordinates import Dimensions, Heading
from smarts.core.road_map import Waypoint
from smarts.core.utils.math import (
    radians_to_vec,
    signed_dist_to_line,
    vec_to_radians,
)
from smarts.env.wrappers.format_action import FormatAction
from smarts.env.wrappers.format_obs import FormatObs
from smarts.env.wrappers.frame_stack import FrameStack

from agent_runtime.main import act_all
from agent_runtime.smarts_compat import SandboxEnv, SmartsAdapter, agent_interface
from submissions.sample import sample_observation


def test_heading_is_a_wrapped_float_with_smarts_methods() -> None:
    assert Heading(3 * math.pi / 2) == pytest.approx(-math.pi / 2)
    assert isinstance(Heading(1.0), float)
    assert Heading(0.0).direction_vector() == pytest.approx([0.0, 1.0])  # 0 = north
    assert Heading(math.pi / 2).direction_vector() == pytest.approx([-1.0, 0.0])  # west
    assert Heading(math.pi / 4).relative_to(Heading(math.pi)) == pytest.approx(-3 * math.pi / 4)
    assert Heading.from_sumo(90).as_sumo == pytest.approx(90)  # SUMO: 90 = east, clockwise
    assert Heading.from_sumo(90) == pytest.approx(-math.pi / 2)


def test_math_utils_use_north_zero_headings() -> None:
    assert radians_to_vec(math.pi) == pytest.approx([0.0, -1.0])
    assert vec_to_radians([1.0, 0.0]) == pytest.approx(3 * math.pi / 2)  # east, in [0, 2 pi)
    # Left of a line pointing north is west: positive.
    assert signed_dist_to_line([-2.0, 5.0], [0.0, 0.0], [0.0, 1.0]) == pytest.approx(2.0)
    assert signed_dist_to_line([3.0, 5.0], [0.0, 0.0], [0.0, 1.0]) == pytest.approx(-3.0)


def test_dimensions_and_waypoint_methods() -> None:
    assert Dimensions(4.5, 1.8, 1.5).as_lwh == (4.5, 1.8, 1.5)
    wp = Waypoint(np.array([10.0, 0.0]), Heading(0.0), "E1_0", 3.2, 13.9, 0, 5.0)
    assert wp.dist_to([13.0, 4.0, 0.0]) == pytest.approx(5.0)
    assert wp.signed_lateral_error([9.0, 2.0]) == pytest.approx(1.0)  # 1 m west: left
    assert wp.relative_heading(0.5) == pytest.approx(0.5)


def adapted(**options):
    native = sample_observation(("Agent_0", "Agent_1"), rasters=True, img_pixels=64)
    for o in native.values():
        points = np.full((300, 3), 5.0)
        o["lidar_point_cloud"] = {
            "points": points,
            "hits": np.arange(300) % 2 == 0,
            "origins": np.zeros((300, 3)),
            "ends": np.ones((300, 3)),
        }
        o["road_waypoints"] = {"E1_0": [o["waypoint_paths"][0]]}
    return SmartsAdapter(img_pixels=64, img_meters=32.0).observations(native)


class Exchange:
    """SandboxEnv's runtime side, playing back fixed observations."""

    def __init__(self, obs) -> None:
        self.obs = obs
        self.sent = []

    def first_observations(self):
        return self.obs

    def answer(self, actions) -> None:
        self.sent.append(actions)

    def next(self):
        return self.obs


def test_the_kits_wrappers_take_every_observation_the_adapter_builds() -> None:
    obs = adapted()
    options = {
        "top_down_rgb": True,
        "occupancy_grid_map": True,
        "drivable_area_grid_map": True,
        "lidar_point_cloud": True,
        "img_pixels": 64,
        "img_meters": 32.0,
    }
    interface = agent_interface(options, "TargetPose")
    exchange = Exchange(obs)
    env = SandboxEnv(exchange, dict.fromkeys(obs, interface))
    env = FormatAction(FormatObs(env), ActionSpaceType["TargetPose"])
    env = FrameStack(env, num_stack=2)
    first = env.reset()
    assert set(first) == {"Agent_0", "Agent_1"} and len(first["Agent_0"]) == 2
    std = first["Agent_0"][-1]
    assert set(std) == {
        "distance_travelled",
        "ego_vehicle_state",
        "events",
        "mission",
        "drivable_area_grid_map",
        "lidar_point_cloud",
        "neighborhood_vehicle_states",
        "occupancy_grid_map",
        "top_down_rgb",
        "waypoint_paths",
    }
    assert std["top_down_rgb"].shape == (64, 64, 3)
    assert std["occupancy_grid_map"].shape == (64, 64, 1)
    assert std["lidar_point_cloud"]["hit"].sum() == 150
    assert np.all(std["lidar_point_cloud"]["point_cloud"][1] == 0)  # a miss: inf -> 0
    assert std["waypoint_paths"]["pos"].shape == (4, 20, 3)
    assert std["neighborhood_vehicle_states"]["box"].shape == (10, 3)
    assert std["ego_vehicle_state"]["box"] == pytest.approx([4.5, 1.8, 1.5])
    assert std["mission"]["goal_pos"].shape == (3,)
    assert env.observation_space["Agent_0"]["top_down_rgb"].shape == (64, 64, 3)
    _, rewards, dones, _ = env.step({k: np.array([1.0, 2.0, 0.0, 0.1]) for k in first})
    assert exchange.sent[0]["Agent_0"].dtype == np.float32  # as SMARTS's FormatAction casts
    assert dones["__all__"] is False and set(rewards) == {"Agent_0", "Agent_1"}
    # Raster metadata: SMARTS's resolution [m/px] and the ego as the camera.
    rgb = obs["Agent_0"].top_down_rgb
    assert rgb.metadata.resolution == 0.5 and rgb.metadata.width == 64
    assert obs["Agent_0"].road_waypoints.lanes["E1_0"][0][0].lane_id == "E1_0"


class Looping:
    """A policy that loops over its agents, as competition policies did."""

    def __init__(self, bad: str) -> None:
        self.bad = bad
        self.calls: list[list[str]] = []

    def act(self, obs):
        self.calls.append(sorted(obs))
        out = {}
        for agent_id, o in obs.items():
            if agent_id == self.bad:
                raise KeyError(f"cannot drive {o['id']}")
            out[agent_id] = [1.0]
        return out


def test_a_failure_is_blamed_on_the_agent_the_policy_was_handling() -> None:
    obs = {f"Agent_{i}": {"id": f"Agent_{i}"} for i in range(3)}
    policy = Looping("Agent_1")
    message = act_all(policy.act, obs)
    assert message["actions"] == {"Agent_0": [1.0], "Agent_2": [1.0]}
    assert list(message["failed"]) == ["Agent_1"]
    assert "KeyError: 'cannot drive Agent_1'" in message["failed"]["Agent_1"]
    assert policy.calls == [["Agent_0", "Agent_1", "Agent_2"], ["Agent_0", "Agent_2"]]


def test_a_failure_no_agent_can_be_blamed_for_ends_the_whole_agent() -> None:
    def act(obs):
        raise ValueError(f"broken for all {len(obs)}")

    with pytest.raises(ValueError, match="broken for all 2"):
        act_all(act, {"Agent_0": {}, "Agent_1": {}})
