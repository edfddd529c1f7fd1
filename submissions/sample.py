"""A realistic observation, shaped exactly as the simulator sends it (``docs/protocol.md``).

For participants' own unit tests of a policy, the sandbox tests and the round-trip benchmark.
"""

from __future__ import annotations

import numpy as np

from sim.bev import BevRenderer, EgoPose
from sim.interface import AgentInterface
from sim.road import RoadNetwork
from sim.road.lane import Lane
from sim.vehicle.states import VehicleStates

SAMPLE_LANES = 4
SAMPLE_LANE_WIDTH = 3.2  # [m]
SAMPLE_ROAD_LENGTH = 500.0  # [m] edge E1 runs from x = 0 to here, lanes along +x


def sample_observation(
    agent_ids: tuple[str, ...] = ("Agent_0",),
    *,
    waypoints: int = 50,
    neighbours: int = 20,
    rasters: bool = False,
    img_pixels: int = 256,
    img_meters: float = 64.0,
) -> dict[str, dict]:
    """One observation per agent id: 4 straight waypoint paths of ``waypoints`` (1 m apart,
    lanes 3.2 m wide along +x), ``neighbours`` vehicles spread over the lanes ahead, the ego at
    (100, 0) doing 12 m/s in lane 0. With ``rasters`` it also holds the three BEV rasters of that
    scene (uint8 numpy arrays, rendered by the simulator's own renderer), as an ``agent.yaml``
    asking for all three with ``img_pixels`` and ``img_meters`` would get them."""

    def one(index: int) -> dict:
        paths = [
            [
                {
                    "pos": [100.0 + w, 3.2 * lane + index],
                    "heading": 0.0,
                    "lane_id": f"E1_{lane}",
                    "lane_index": lane,
                    "lane_width": 3.2,
                    "speed_limit": 13.89,
                    "lane_offset": float(w),
                }
                for w in range(waypoints)
            ]
            for lane in range(4)
        ]
        others = [
            {
                "id": f"car-{n}",
                "position": [110.0 + 5 * n, 3.2 * (n % 4), 0.0],
                "heading": 0.01 * n,
                "speed": 10.0 + n % 3,
                "bounding_box": [4.5, 1.8, 1.5],
                "road_id": "E1",
                "lane_id": f"E1_{n % 4}",
                "lane_index": n % 4,
            }
            for n in range(neighbours)
        ]
        return {
            "dt": 0.1,
            "step_count": 12,
            "elapsed_sim_time": 1.2,
            "distance_travelled": 14.5,
            "done": False,
            "events": {
                "collisions": [],
                "off_road": False,
                "off_route": False,
                "on_shoulder": False,
                "wrong_way": False,
                "not_moving": False,
                "reached_goal": False,
                "reached_max_episode_steps": False,
            },
            "ego_vehicle_state": {
                "id": f"Agent_{index}",
                "position": [100.0, 0.0, 0.0],
                "heading": 0.0,
                "speed": 12.0,
                "bounding_box": [4.5, 1.8, 1.5],
                "steering": 0.0,
                "yaw_rate": 0.0,
                "road_id": "E1",
                "lane_id": "E1_0",
                "lane_index": 0,
                "lane_position": [100.0, 0.1],
                "linear_velocity": [12.0, 0.0, 0.0],
                "angular_velocity": [0.0, 0.0, 0.0],
                "linear_acceleration": [0.1, 0.0, 0.0],
                "angular_acceleration": [0.0, 0.0, 0.0],
                "linear_jerk": [0.0, 0.0, 0.0],
                "angular_jerk": [0.0, 0.0, 0.0],
                "mission": {
                    "start": [0.0, 0.0, 0.0],
                    "goal": {"position": [400.0, 0.0], "radius": 5.0},
                    "route": ["E0", "E1", "E2"],
                },
            },
            "neighborhood_vehicle_states": others,
            "waypoint_paths": paths,
        }

    observations = {agent_id: one(i) for i, agent_id in enumerate(agent_ids)}
    if rasters:
        for obs in observations.values():
            obs.update(_sample_rasters(obs, img_pixels, img_meters))
    return observations


def _sample_rasters(obs: dict, img_pixels: int, img_meters: float) -> dict[str, np.ndarray]:
    """The rasters of ``obs``'s scene on a straight 4-lane road (no SUMO needed)."""
    lanes = {
        f"E1_{i}": Lane(
            id=f"E1_{i}",
            edge_id="E1",
            index=i,
            centreline=np.array(
                [[0.0, SAMPLE_LANE_WIDTH * i], [SAMPLE_ROAD_LENGTH, SAMPLE_LANE_WIDTH * i]]
            ),
            width=SAMPLE_LANE_WIDTH,
            speed_limit=13.89,
            is_internal=False,
            is_shoulder=False,
        )
        for i in range(SAMPLE_LANES)
    }
    interface = AgentInterface(
        top_down_rgb=True,
        occupancy_grid_map=True,
        drivable_area_grid_map=True,
        img_pixels=img_pixels,
        img_meters=img_meters,
    )
    ego = obs["ego_vehicle_state"]
    others = obs["neighborhood_vehicle_states"]
    renderer = BevRenderer(
        RoadNetwork(lanes, []), interface, {ego["id"]: tuple(ego["mission"]["route"])}
    )
    near = VehicleStates(
        [o["id"] for o in others],
        np.array([o["position"][0] for o in others], float),
        np.array([o["position"][1] for o in others], float),
        np.array([o["heading"] for o in others], float),
        np.array([o["speed"] for o in others], float),
        np.array([o["bounding_box"][0] for o in others], float),
        np.array([o["bounding_box"][1] for o in others], float),
        [o["lane_id"] for o in others],
    )
    x, y, _ = ego["position"]
    length, width, _ = ego["bounding_box"]
    return renderer.render(ego["id"], EgoPose(x, y, ego["heading"], length, width), near)
