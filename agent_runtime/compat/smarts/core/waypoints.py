"""Where SMARTS before 0.5 kept ``Waypoint`` (``smarts.core.waypoints``); the same type."""

from smarts.core.road_map import Waypoint

__all__ = ["Waypoint"]
