"""A wrapper of the submission's own, reading SMARTS's observation by attribute (before
FormatObs turns it into arrays), as the kit's ``SaveObs`` did."""

import gym
from smarts.core.road_map import Waypoint
from smarts.core.sensors import Observation


class SaveGoal(gym.ObservationWrapper):
    def __init__(self, env):
        super().__init__(env)
        self.goals = {}

    def observation(self, obs):
        for agent_id, agent_obs in obs.items():
            assert isinstance(agent_obs, Observation), type(agent_obs)
            ego = agent_obs.ego_vehicle_state
            self.goals[agent_id] = ego.mission.goal.position
            first = agent_obs.waypoint_paths[0][0]
            assert isinstance(first, Waypoint)
            # SMARTS's Heading and Waypoint methods, in SMARTS's frame.
            assert abs(first.relative_heading(ego.heading)) < 1.6
            assert ego.bounding_box.as_lwh[0] > 0
            assert agent_obs.top_down_rgb.data.shape == (64, 64, 3)
            assert agent_obs.top_down_rgb.metadata.resolution == 0.5
            points, hits, rays = agent_obs.lidar_point_cloud
            assert len(points) == len(hits) == len(rays) == 300
            assert ego.lane_id in agent_obs.road_waypoints.lanes or ego.lane_id.startswith(":")
            for neighbour in agent_obs.neighborhood_vehicle_states:
                assert neighbour.lane_position is not None
        return obs
