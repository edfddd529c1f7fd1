"""The ``smarts`` and ``gym`` compatibility packages (``agent_runtime/compat/``) behave as SMARTS's
documentation says, and the kit's wrappers accept what the adapter builds."""

from __future__ import annotations

import math

import gym
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
from smarts.env.wrappers.format_obs import LATER_KEYS, FormatObs
from smarts.env.wrappers.frame_stack import FrameStack

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


COMP1_KEYS = {"dist", "ego", "events", "mission", "dagm", "lidar", "neighbors", "ogm", "rgb"}
COMP1_KEYS |= {"waypoints"}


@pytest.mark.parametrize("key_set", ["comp-1", "later"])
def test_the_kits_wrappers_take_every_observation_the_adapter_builds(key_set) -> None:
    obs = adapted()
    options = {
        "top_down_rgb": True,
        "occupancy_grid_map": True,
        "drivable_area_grid_map": True,
        "lidar_point_cloud": True,
        "img_pixels": 64,
        "img_meters": 32.0,
        "format_obs_keys": key_set,
    }
    interface = agent_interface(options, "TargetPose")
    exchange = Exchange(obs)
    env = SandboxEnv(exchange, dict.fromkeys(obs, interface), options)
    env = FormatAction(FormatObs(env), ActionSpaceType["TargetPose"])
    env = FrameStack(env, num_stack=2)
    first = env.reset()
    assert set(first) == {"Agent_0", "Agent_1"} and len(first["Agent_0"]) == 2
    std = first["Agent_0"][0]
    key = {k: k for k in COMP1_KEYS} if key_set == "comp-1" else LATER_KEYS
    assert set(std) == {key[k] for k in COMP1_KEYS}
    assert std[key["rgb"]].shape == (64, 64, 3)
    assert std[key["ogm"]].shape == (64, 64, 1)
    assert std[key["lidar"]]["hit"].sum() == 150
    assert np.all(std[key["lidar"]]["point_cloud"][1] == 0)  # a miss: inf -> 0
    assert std[key["waypoints"]]["pos"].shape == (4, 20, 3)
    assert std[key["neighbors"]]["box"].shape == (10, 3)
    assert std[key["ego"]]["box"] == pytest.approx([4.5, 1.8, 1.5])
    assert (
        std[key["ego"]]["pos"].dtype == np.float64 and std[key["ego"]]["speed"].dtype == np.float32
    )
    assert std["mission"]["goal_pos"].shape == (3,)
    # FrameStack's space: per agent a Tuple of num_stack FormatObs spaces, which hold each value.
    stacked = env.observation_space["Agent_0"]
    assert isinstance(stacked, gym.spaces.Tuple) and len(stacked) == 2
    assert stacked[0][key["rgb"]].shape == (64, 64, 3)
    assert stacked[0][key["waypoints"]]["pos"].dtype == np.float64
    for name, space in stacked[0].spaces.items():
        if not isinstance(space, gym.spaces.Dict):
            assert space.contains(std[name]), name
    _, rewards, dones, _ = env.step({k: np.array([1.0, 2.0, 0.0, 0.1]) for k in first})
    assert exchange.sent[0]["Agent_0"].dtype == np.float32  # as SMARTS's FormatAction casts
    assert dones["__all__"] is False and set(rewards) == {"Agent_0", "Agent_1"}
    # Raster metadata: SMARTS's resolution [m/px] and the ego as the camera.
    rgb = obs["Agent_0"].top_down_rgb
    assert rgb.metadata.resolution == 0.5 and rgb.metadata.width == 64
    assert obs["Agent_0"].road_waypoints.lanes["E1_0"][0][0].lane_id == "E1_0"


def test_frame_stack_puts_the_newest_frame_first_as_smarts_does() -> None:
    class Counter(gym.Env):
        def __init__(self) -> None:
            self.agent_specs = {"Agent_0": None}
            self.t = 0

        def reset(self):
            self.t = 0
            return {"Agent_0": self.t}

        def step(self, action):
            self.t += 1
            return {"Agent_0": self.t}, {}, {"__all__": False}, {}

    env = FrameStack(Counter(), num_stack=3)
    assert env.reset() == {"Agent_0": (0, 0, 0)}
    assert env.step({})[0] == {"Agent_0": (1, 0, 0)}
    assert env.step({})[0] == {"Agent_0": (2, 1, 0)}
    assert env.reset() == {"Agent_0": (0, 0, 0)}
    with pytest.raises(AssertionError):
        FrameStack(Counter(), num_stack=1)


def test_gym_has_the_space_base_and_the_spaces_full_constructors() -> None:
    assert issubclass(gym.spaces.Box, gym.Space) and gym.Space is gym.spaces.Space
    box = gym.spaces.Box(low=-1.0, high=np.array([1.0, 2.0]), shape=(2,), dtype=np.float64, seed=3)
    assert box.shape == (2,) and box.dtype == np.float64 and box.is_bounded()
    assert (
        box.sample().tolist()
        == gym.spaces.Box(-1.0, np.array([1.0, 2.0]), None, np.float64, 3).sample().tolist()
    )
    assert gym.spaces.Discrete(n=4, seed=1).contains(3)
    assert gym.spaces.MultiBinary(n=5, seed=1).sample().shape == (5,)
    assert gym.spaces.MultiDiscrete(nvec=[2, 3], dtype=np.int64, seed=1).contains([1, 2])
    pair = gym.spaces.Tuple(spaces=[gym.spaces.Discrete(2)] * 2, seed=1)
    assert len(pair.sample()) == 2
    # gym 0.21 sorts a plain dict's keys; an OrderedDict or keywords keep theirs.
    assert list(gym.spaces.Dict({"b": box, "a": box}).keys()) == ["a", "b"]
    assert list(gym.spaces.Dict(b=box, a=box).keys()) == ["a", "b"]

    class Named(gym.Wrapper):
        pass

    class Base(gym.Env):
        saved = 7

    wrapped = Named(Base())
    wrapped.observation_space = box
    assert wrapped.observation_space is box and wrapped.action_space is None
    assert wrapped.saved == 7  # attributes of the wrapped env, as the kit's Action wrapper reads


def test_smarts_colours_are_those_the_rasters_are_drawn_in() -> None:
    from smarts.core.colors import Colors, SceneColors

    from sim.bev import SMARTS_COLOURS

    def rgb(colour) -> tuple[int, ...]:
        return tuple(round(c * 255) for c in colour.value[:3])

    assert rgb(SceneColors.Road) == SMARTS_COLOURS["road"]
    assert rgb(SceneColors.SocialVehicle) == SMARTS_COLOURS["vehicle"]
    assert rgb(SceneColors.Agent) == SMARTS_COLOURS["ego"] == SMARTS_COLOURS["mission_agent"]
    assert Colors.GreenTransparent.value[3] == 0.3


# Every public name SMARTS comp-1 defines in the modules 2022 agents import (the simulator's
# machinery aside: docs/smarts-compat.md names what is left out).
COMP1_PUBLIC_NAMES = {
    "smarts.core": "current_seed seed gen_id",
    "smarts.core.utils.math": (
        "CubicPolynomial batches circular_mean clip comb constrain_angle euclidean_distance "
        "evaluate_bezier fast_quaternion_from_angle get_bezier_curve "
        "get_linear_segments_for_range inplace_unwrap is_close lerp line_intersect "
        "line_intersect_vectorized low_pass_filter min_angles_difference_signed mult_quat "
        "position_to_ego_frame radians_to_vec ray_boundary_intersect rotate_cw_around_point "
        "rotate_quat round_param_for_dt rounder_for_dt safe_division sign signed_dist_to_line "
        "squared_dist vec_2d vec_to_radians world_position_from_ego_frame wrap_value "
        "yaw_from_quaternion"
    ),
    "smarts.core.colors": "Colors SceneColors",
    "smarts.core.controllers": "ActionSpaceType METER_PER_SECOND_TO_KM_PER_HR",
    "smarts.core.agent_interface": (
        "AgentInterface AgentType AgentsAliveDoneCriteria AgentsListAlive DoneCriteria "
        "DrivableAreaGridMap EventConfiguration LanePositions Lidar NeighborhoodVehicles OGM RGB "
        "RoadWaypoints Signals Waypoints Accelerometer"
    ),
    "smarts.core.sensors": (
        "LANE_ID_CONSTANT LANE_INDEX_CONSTANT ROAD_ID_CONSTANT Observation "
        "EgoVehicleObservation VehicleObservation TopDownRGB OccupancyGridMap "
        "DrivableAreaGridMap GridMapMetadata RoadWaypoints Vias ViaPoint SignalObservation"
    ),
    "smarts.core.plan": (
        "Start Goal EndlessGoal PositionalGoal Via Mission PlanningError VehicleSpec"
    ),
    "smarts.env.wrappers.format_obs": "FormatObs get_spaces intrfc_to_stdobs",
    "smarts.env.wrappers.format_action": "FormatAction",
    "smarts.env.wrappers.frame_stack": "FrameStack",
}


@pytest.mark.parametrize("module", sorted(COMP1_PUBLIC_NAMES))
def test_the_modules_agents_import_have_every_public_name_of_comp1(module) -> None:
    imported = __import__(module, fromlist=["_"])
    missing = [n for n in COMP1_PUBLIC_NAMES[module].split() if not hasattr(imported, n)]
    assert missing == []


def test_comp1_math_helpers_compute_what_their_names_say() -> None:
    from smarts.core import utils

    m = utils.math
    assert m.rotate_cw_around_point((1.0, 0.0), math.pi / 2) == pytest.approx([0.0, -1.0])
    quarter_turn = [math.cos(math.pi / 4), 0.0, 0.0, math.sin(math.pi / 4)]  # about +z
    assert m.rotate_quat(quarter_turn, [1.0, 0.0, 0.0]) == pytest.approx([0.0, 1.0, 0.0])
    angles = np.array([0.0, 3.0, -3.0, 0.5])
    assert m.inplace_unwrap(angles) is angles and angles == pytest.approx(
        np.unwrap([0.0, 3.0, -3.0, 0.5])
    )
    assert (m.round_param_for_dt(0.1), m.round_param_for_dt(100)) == (1, -2)
    assert m.rounder_for_dt(0.1)(0.30000000004) == 0.3
    assert m.CubicPolynomial.from_list([1, 2, 3, 4]).eval(2) == 1 + 4 + 12 + 32
    points = np.array([[0.0, 0.0], [1.0, 2.0], [3.0, 0.0]])
    curve = m.get_bezier_curve(points)
    assert curve(0.0) == pytest.approx(points[0]) and curve(1.0) == pytest.approx(points[-1])
    assert curve(0.5) == pytest.approx([1.25, 1.0])
    starts, ends = np.array([[0.0, -1.0], [5.0, -1.0]]), np.array([[0.0, 1.0], [5.0, 1.0]])
    assert m.line_intersect_vectorized(np.array([-1.0, 0.0]), np.array([1.0, 0.0]), starts, ends)
    assert not m.line_intersect_vectorized(np.array([1.0, 0.0]), np.array([2.0, 0.0]), starts, ends)
    boundary = np.array([[2.0, -5.0], [2.0, 5.0], [4.0, 5.0], [4.0, -5.0]])
    far = m.ray_boundary_intersect([0.0, 0.0], [10.0, 0.0], boundary[2:], early_return=False)
    assert far == pytest.approx([4.0, 0.0])
    assert m.ray_boundary_intersect([0.0, 0.0], [10.0, 0.0], boundary, early_return=False)[
        0
    ] == pytest.approx(2.0)
    assert m.sign(-0.5) == -1 and m.sign(0) == 1 and m.comb(5, 2) == 10
    assert m.circular_mean([np.array([0.0, 1.0])]) == pytest.approx(0.0)  # north
    assert m.low_pass_filter(1.0, 0.0, 2.0, 0.1) == pytest.approx(0.2)
