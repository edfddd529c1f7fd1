"""Waypoint follower written against the SMARTS 2022 interface (``observation_format: smarts2022``).

Everything is read by attribute, as SMARTS agents do, and every heading is in SMARTS's frame:
0 = +y (north), counter-clockwise, so the unit direction of heading h is (-sin h, cos h). It
checks that frame on its own motion and that ``distance_travelled`` is the distance of one step,
and raises if either is wrong, so a broken conversion fails loudly.
"""

import math

import numpy as np

CRUISE = 8.0  # [m/s]
DT = 0.1  # [s]
GAP = 12.0  # [m] keep at least this far behind a vehicle on the path


def direction(heading: float) -> np.ndarray:
    """Unit vector of a SMARTS heading (0 = north)."""
    return np.array([-math.sin(heading), math.cos(heading)])


class Policy:
    def act(self, obs):
        return {agent_id: self.drive(o) for agent_id, o in obs.items()}

    def drive(self, o):
        ego = o.ego_vehicle_state
        xy = np.asarray(ego.position[:2])
        velocity = np.asarray(ego.linear_velocity[:2])
        # A frame error is 90 degrees or more; turning TargetPose steps differ by far less.
        if ego.speed > 1.0 and float(direction(ego.heading) @ velocity) < 0.5 * ego.speed:
            raise ValueError(f"heading {ego.heading:.2f} is not SMARTS's (velocity {velocity})")
        if o.distance_travelled > ego.speed * DT + 1.0:
            raise ValueError(f"distance_travelled {o.distance_travelled} is not one step's")
        path = self.my_path(o, xy)
        speed = min(CRUISE, ego.speed + 2.0 * DT)
        ahead = self.gap_ahead(o, path, xy)
        if ahead < GAP:
            speed = max(0.0, ego.speed - 4.0 * DT) if ahead < GAP / 2 else min(speed, ego.speed)
        # Step `speed * DT` metres towards a point a second or so ahead on the path (a lane
        # change then takes a few steps), facing the way we move: SMARTS heading of (dx, dy)
        # is atan2(-dx, dy).
        points = np.array([wp.pos for wp in path])
        nearest = int(np.argmin(np.hypot(*(points - xy).T)))
        target = points[min(nearest + max(4, round(speed)), len(path) - 1)]
        to_target = target - xy
        distance = float(np.hypot(*to_target))
        step = speed * DT
        if distance < 1e-6 or step < 1e-6:
            return [float(xy[0]), float(xy[1]), float(ego.heading), DT]
        dx, dy = to_target * min(1.0, step / distance)
        return [float(xy[0] + dx), float(xy[1] + dy), math.atan2(-dx, dy), DT]

    @staticmethod
    def my_path(o, xy):
        paths = [p for p in o.waypoint_paths if p]
        goal = np.asarray(o.ego_vehicle_state.mission.goal.position[:2])
        if float(np.hypot(*(goal - xy))) < 60.0:  # near the goal: the path that passes it
            return min(paths, key=lambda p: min(float(np.hypot(*(wp.pos - goal))) for wp in p))
        own = [p for p in paths if p[0].lane_id == o.ego_vehicle_state.lane_id]
        if own:
            return own[0]
        return min(paths, key=lambda p: float(np.hypot(*(np.asarray(p[0].pos) - xy))))

    @staticmethod
    def gap_ahead(o, path, xy):
        lanes = {wp.lane_id for wp in path}
        heading = direction(o.ego_vehicle_state.heading)
        gaps = [
            float((np.asarray(n.position[:2]) - xy) @ heading)
            for n in o.neighborhood_vehicle_states
            if n.lane_id in lanes
        ]
        return min((g for g in gaps if g > 0.0), default=math.inf)
