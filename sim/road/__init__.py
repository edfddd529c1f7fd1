"""Road geometry: lanes and the network they form (see :class:`RoadNetwork`)."""

from sim.road.lane import Lane, angle_between, wrap_angle
from sim.road.network import LanePosition, RoadNetwork, lane_surface

__all__ = ["Lane", "LanePosition", "RoadNetwork", "angle_between", "lane_surface", "wrap_angle"]
