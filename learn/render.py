"""``render_mode="rgb_array"``: a top-down picture of the episode around the followed agent,
drawn with the rasteriser of the ``top_down_rgb`` observation (``sim.bev``) at a size for
people, with the goal marked. Heading-up and ego-centred, as the agent sees its world.

Drawn inside the simulator session after each reset and step (before a finished episode's
simulator closes), so the terminal picture exists and a simulator in a child process sends it
back with its reply."""

from __future__ import annotations

import cv2
import numpy as np

from sim.bev import BevRenderer, EgoPose
from sim.interface import AgentInterface
from sim.vehicle.states import VehicleStates

RENDER_PIXELS = 400  # [px] square
RENDER_METERS = 80.0  # [m] across
GOAL_COLOUR = (60, 220, 90)  # RGB


class TopView:
    """The picture-maker of one episode (its road rasterised once)."""

    def __init__(self, sim, pixels: int = RENDER_PIXELS, meters: float = RENDER_METERS) -> None:
        interface = AgentInterface(
            top_down_rgb=True, img_pixels=pixels, img_meters=meters, observation_radius=meters
        )
        routes = {v.id: v.mission.route for v in sim.vehicles}
        self._bev = BevRenderer(sim.road, interface, routes)
        self.pixels = pixels

    def picture(self, sim, agent_id: str) -> np.ndarray:
        """(pixels, pixels, 3) uint8 RGB around ``agent_id`` (where it ended, once done)."""
        ego_vehicle = next(v for v in sim.vehicles if v.id == agent_id)
        pose, dims = ego_vehicle.pose, ego_vehicle.mission.vehicle
        ego = EgoPose(pose.x, pose.y, pose.heading, dims.length, dims.width)
        others = VehicleStates.concat([sim.background_states(), _other_agents(sim, agent_id)])
        image = self._bev.render(agent_id, ego, others)["top_down_rgb"].copy()
        goal = ego_vehicle.mission.goal
        centre = self._bev.to_image(ego, np.array([goal.position], float))[0]
        radius = max(3, round(goal.radius * self._bev.res))
        cv2.circle(image, tuple(round(c) for c in centre), radius, GOAL_COLOUR, 2)
        cv2.drawMarker(
            image, tuple(round(c) for c in centre), GOAL_COLOUR, cv2.MARKER_CROSS, radius, 1
        )
        return image


def _other_agents(sim, agent_id: str) -> VehicleStates:
    """Mission vehicles on the road other than the followed one (drawn in their own colour)."""
    live = [v for v in sim.live if v.id != agent_id]
    if not live:
        return VehicleStates.empty()
    return VehicleStates(
        [v.id for v in live],
        np.array([v.pose.x for v in live]),
        np.array([v.pose.y for v in live]),
        np.array([v.pose.heading for v in live]),
        np.array([v.pose.speed for v in live]),
        np.array([v.mission.vehicle.length for v in live]),
        np.array([v.mission.vehicle.width for v in live]),
        ["" for _ in live],
    )
