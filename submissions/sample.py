"""A realistic observation, shaped exactly as the simulator sends it (``docs/protocol.md``).

For participants' own unit tests of a policy, the sandbox tests and the round-trip benchmark.
"""

from __future__ import annotations


def sample_observation(
    agent_ids: tuple[str, ...] = ("Agent_0",), *, waypoints: int = 50, neighbours: int = 20
) -> dict[str, dict]:
    """One observation per agent id: 4 straight waypoint paths of ``waypoints`` (1 m apart,
    lanes 3.2 m wide along +x), ``neighbours`` vehicles spread over the lanes ahead, the ego at
    (100, 0) doing 12 m/s in lane 0."""

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

    return {agent_id: one(i) for i, agent_id in enumerate(agent_ids)}
