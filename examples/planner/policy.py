"""Reference rule-based planner: the strongest baseline of Driving Arena, using observations only.

Per agent and step:
1. Paths: the waypoint paths of the observation (one per lane of the ego's road, continuing along
   the route) become polylines with arc length; anything can be projected onto them.
2. Lane choice: the lane whose path, extrapolated with its own curvature, passes nearest the goal;
   far from the goal a faster adjacent lane is taken to overtake slow traffic; lanes that end or
   are shoulders are left. A lane change starts only when the gaps ahead and behind in the target
   lane are safe for both vehicles.
3. Speed: IDM on the nearest vehicle ahead inside the ego's corridor (current and target lane),
   the speed limit and a curvature limit; the end of a lane is a stopped obstacle.
4. Junctions: approaching a turn (or a road with higher priority), stop at the stop line, then go
   only when no other vehicle, predicted at constant velocity, will be near a point of our path
   while we pass it.
5. Action: TargetPose one step along the target path, easing the lateral offset to the target
   lane at a bounded lateral speed.

Only numpy and the standard library.
"""

from __future__ import annotations

import itertools
import math
from operator import itemgetter

import numpy as np

DT = 0.1  # [s]
A_MAX = 2.5  # [m/s^2] IDM acceleration
B_COMF = 3.0  # [m/s^2] IDM comfortable deceleration
B_MAX = 7.0  # [m/s^2] hardest braking we command
HEADWAY = 1.2  # [s] IDM time headway
S0 = 3.0  # [m] IDM standstill gap
A_LAT = 2.5  # [m/s^2] lateral acceleration allowed in curves
LAT_SPEED = 1.2  # [m/s] lateral speed of a lane change
# [m/s^2] lateral acceleration ramping a lane change's lateral speed up and down: a TargetPose
# vehicle moves exactly to the pose, so a lateral speed switched on at once is a jerk spike.
LAT_ACCEL = 3.0
GOAL_LANE_DISTANCE = 250.0  # [m] within this distance only the goal lane counts
STOP_SPEED = 0.3  # [m/s] counts as stopped at a stop line
# [m] another vehicle's centre this near a point of our path blocks it (less than a lane width:
# traffic on a parallel lane does not)
CONFLICT_RADIUS = 2.4
SHOULDER_WIDTH = 3.0  # [m] narrower lanes are shoulders
FULL_PATH_WAYPOINTS = 50  # waypoints_per_path of agent.yaml


def menger_curvature(points: np.ndarray) -> float:
    """Signed curvature [1/m] (left positive) of the circle through the first, middle and last
    of ``points`` (n, 2): positions are exact lane points, waypoint headings step at corners."""
    if len(points) < 3:
        return 0.0
    (ax, ay), (bx, by), (cx, cy) = points[[0, len(points) // 2, -1]].tolist()
    cross = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)
    ba, cb, ca = np.hypot([bx - ax, cx - bx, cx - ax], [by - ay, cy - by, cy - ay]).tolist()
    sides = ba * cb * ca
    return float(2.0 * cross / sides) if sides > 1e-6 else 0.0


def wrap(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi


def on_route(lane_ids: list[str], route: tuple[str, ...]) -> bool:
    """Whether a path of ``lane_ids`` follows ``route``: every road on it is a route road up to
    the route's last one. Past that it may go anywhere: a route cut from a recording ends where
    the recording did, mid-map, and the road beyond leads to the goal as well as any."""
    roads = route[-1:]
    for lane in dict.fromkeys(lane_ids):  # each lane once, in order: the first visit decides
        if lane.startswith(":"):
            continue
        edge = lane.rsplit("_", 1)[0]
        if edge in roads:
            return True
        if edge not in route:
            return False
    return True


class Path:
    """A waypoint path as a polyline: points (n, 2) [m], headings (n,), arc length (n,) [m]."""

    def __init__(self, waypoints: list[dict], lane_ids: list[str] | None = None) -> None:
        self.lane_ids = lane_ids or [w["lane_id"] for w in waypoints]
        n = len(waypoints)
        positions = itertools.chain.from_iterable(map(itemgetter("pos"), waypoints))
        self.xy = np.fromiter(positions, float).reshape(n, -1)[:, :2]
        self.heading = np.fromiter(map(itemgetter("heading"), waypoints), float, n)
        # Segments as separate x and y arrays: the projection's arithmetic on (points, segments)
        # grids is then a few whole-array operations.
        self._ax, self._ay = self.xy[:-1, 0].copy(), self.xy[:-1, 1].copy()
        self._abx = self.xy[1:, 0] - self._ax  # [m]
        self._aby = self.xy[1:, 1] - self._ay
        self._ab_len = np.hypot(self._abx, self._aby)  # [m]
        self._ab_len2 = np.maximum(self._abx * self._abx + self._aby * self._aby, 1e-9)
        self.s = np.concatenate([[0.0], np.cumsum(self._ab_len)])
        self.lane_index = int(waypoints[0]["lane_index"])
        self.width = float(waypoints[0].get("lane_width") or 3.2)
        self._waypoints = waypoints
        self.length = float(self.s[-1])
        # Paths are cut at the observation's waypoint count: a shorter one is a lane that ends.
        self.ends = len(waypoints) < FULL_PATH_WAYPOINTS
        self._projected: tuple[list, list[tuple[float, float]]] | None = None
        self._memo: dict[tuple[float, float], tuple[float, float]] = {}
        # Computed when first needed (plain attributes: functools.cached_property takes a lock
        # on every read before Python 3.12).
        self._limits: np.ndarray | None = None
        self._end_curvature: float | None = None
        self._end_arc: tuple[float, float, float] | None = None

    @property
    def limits(self) -> np.ndarray:
        """Speed limit [m/s] at each waypoint (only the current and target paths' are read)."""
        if self._limits is None:
            limits = [w.get("speed_limit") or 13.9 for w in self._waypoints]
            self._limits = np.array(limits, dtype=float)
        return self._limits

    @property
    def end_curvature(self) -> float:
        """Curvature [1/m] at the path's end (read when a point lies beyond it)."""
        if self._end_curvature is None:
            self._end_curvature = self._longest_lane_curvature()
        return self._end_curvature

    def _longest_lane_curvature(self) -> float:
        """Edge shapes are arcs and straights; junction connections are not: the curvature of the
        longest stretch of one lane (normal, not internal) on the path."""
        runs, start = [], 0
        for lane, run in itertools.groupby(self.lane_ids):
            n = len(list(run))
            if not lane.startswith(":"):
                runs.append((n, start, start + n))
            start += n
        _, a, b = max(runs) if runs else (0, 0, len(self.xy))
        return menger_curvature(self.xy[a:b])

    def direction(self, i: int) -> float:
        """Heading [rad] of the chord from waypoint ``i`` to ``i + 2`` (clamped to the path)."""
        i = min(max(i, 0), len(self.xy) - 3) if len(self.xy) >= 3 else 0
        j = min(i + 2, len(self.xy) - 1)
        dx, dy = self.xy[j] - self.xy[i]
        return math.atan2(dy, dx) if (dx or dy) else float(self.heading[i])

    def point(self, s: float) -> tuple[float, float, float]:
        """(x, y, heading) at arc length ``s``; straight extension beyond both ends."""
        if len(self.xy) == 1 or s <= 0.0:
            h = self.heading[0]
            return self.xy[0, 0] + s * math.cos(h), self.xy[0, 1] + s * math.sin(h), h
        if s >= self.length:
            h = self.heading[-1]
            d = s - self.length
            return self.xy[-1, 0] + d * math.cos(h), self.xy[-1, 1] + d * math.sin(h), h
        i = int(self.s.searchsorted(s)) - 1
        s_i = self.s.item(i)
        f = (s - s_i) / max(self.s.item(i + 1) - s_i, 1e-9)
        x, y, h = self.xy.item(i, 0), self.xy.item(i, 1), self.heading.item(i)
        x += f * (self.xy.item(i + 1, 0) - x)
        y += f * (self.xy.item(i + 1, 1) - y)
        h += f * wrap(self.heading.item(i + 1) - h)
        return x, y, h

    def project(self, x: float, y: float) -> tuple[float, float]:
        """(s [m], lateral offset [m], left positive) of a point; extends beyond both ends."""
        key = (x, y)
        if key not in self._memo:
            self._memo[key] = self.project_many(np.array([[x, y]], dtype=float))[0]
        return self._memo[key]

    def project_step(self, points: np.ndarray, others: list[dict]) -> None:
        """Projects ``points``, (2 + n, 2): the ego, the goal and the vehicles ``others``, in one
        pass: each is asked for several times per step (lane choice, lead vehicle, gaps), and one
        segment search is cheaper than several."""
        projected = self.project_many(points)
        ego, goal = points.tolist()[:2]
        self._memo.setdefault((ego[0], ego[1]), projected[0])
        self._memo.setdefault((goal[0], goal[1]), projected[1])
        self._projected = (others, projected[2:])

    def project_many(self, points: np.ndarray) -> list[tuple[float, float]]:
        """:meth:`project` of each of ``points`` (n, 2), the segment search in one pass."""
        if len(self.xy) == 1:
            return [self._extend(p, 0) for p in points.tolist()]
        px, py = points[:, :1], points[:, 1:]  # (n, 1) against (segments,)
        ax, ay, abx, aby = self._ax, self._ay, self._abx, self._aby
        t = (px - ax) * abx
        t += (py - ay) * aby
        t /= self._ab_len2
        np.minimum(np.maximum(t, 0.0, out=t), 1.0, out=t)
        dx = t * abx
        dx += ax
        dx -= px
        dy = t * aby
        dy += ay
        dy -= py
        d = np.hypot(dx, dy)
        out = []
        last = len(abx) - 1
        # Scalars from here on: a handful of points, where numpy's per-call cost dominates.
        for k, (i, p) in enumerate(zip(d.argmin(axis=1).tolist(), points.tolist(), strict=True)):
            t_p = t.item(k, i)
            if i == 0 and t_p <= 0.0:
                out.append(self._extend(p, 0))
            elif i == last and t_p >= 1.0:
                out.append(self._extend_arc(p))
            else:
                seg_len = self._ab_len.item(i)
                den = max(seg_len, 1e-9)
                seg_x, seg_y = abx.item(i) / den, aby.item(i) / den
                r_x, r_y = p[0] - ax.item(i), p[1] - ay.item(i)
                out.append((self.s.item(i) + t_p * seg_len, seg_x * r_y - seg_y * r_x))
        return out

    def project_vehicles(self, others: list[dict]) -> list[tuple[float, float]]:
        """:meth:`project` of each vehicle's position, kept for the last ``others`` list seen."""
        if self._projected is None or self._projected[0] is not others:
            points = np.array([o["position"][:2] for o in others], dtype=float).reshape(-1, 2)
            self._projected = (others, self.project_many(points))
        return self._projected[1]

    def _extend(self, p: list[float], k: int) -> tuple[float, float]:
        """Straight on from waypoint ``k`` along its heading."""
        h = self.heading.item(k)
        c, s = math.cos(h), math.sin(h)
        rel_x, rel_y = p[0] - self.xy.item(k, 0), p[1] - self.xy.item(k, 1)
        return self.s.item(k) + c * rel_x + s * rel_y, c * rel_y - s * rel_x

    def _extend_arc(self, p: list[float]) -> tuple[float, float]:
        """Beyond the end the lane is assumed to keep its end curvature (roads are arcs and
        straights): a straight extension would put cars of the next lane into ours on curves."""
        k = self.end_curvature
        if abs(k) < 1e-4:
            return self._extend(p, len(self.xy) - 1)
        if self._end_arc is None:
            self._end_arc = self._arc_beyond_end(k)
        cx, cy, end_angle = self._end_arc
        sweep = wrap(math.atan2(p[1] - cy, p[0] - cx) - end_angle)
        radius = 1.0 / abs(k)
        lateral = math.copysign(radius - math.hypot(p[0] - cx, p[1] - cy), k)
        return self.length + sweep / k, lateral

    def _arc_beyond_end(self, k: float) -> tuple[float, float, float]:
        """Centre (x, y) [m] of the arc of curvature ``k`` continuing the path, and the angle
        [rad] of the path's end seen from it."""
        x, y = self.xy[-1]
        h = self._end_heading(k)
        cx, cy = x - math.sin(h) / k, y + math.cos(h) / k
        return cx, cy, math.atan2(y - cy, x - cx)

    def _end_heading(self, k: float) -> float:
        """Tangent [rad] at the path's end on an arc of curvature ``k``: the direction of the last
        ~10 m chord turned by half its arc. Waypoint headings are those of the polyline segment
        they lie on, off by up to half a vertex turn, which grows to metres over the 200 m the
        goal may lie beyond the end."""
        i = int(np.searchsorted(self.s, self.length - 10.0))
        i = min(i, len(self.xy) - 2)
        dx, dy = self.xy[-1] - self.xy[i]
        return math.atan2(dy, dx) + 0.5 * k * (self.length - self.s[i])

    def goal_offset(self, gx: float, gy: float) -> float:
        """Lateral distance [m] of the goal from this lane (extended as an arc past the end)."""
        return abs(self.project(gx, gy)[1])

    def junction_span(self) -> tuple[int, int] | None:
        """Waypoint indices (first internal, first after) of the next junction, if any."""
        first = next((i for i, lane in enumerate(self.lane_ids) if lane.startswith(":")), None)
        if first is None:
            return None
        after = next(
            (i for i in range(first, len(self.lane_ids)) if not self.lane_ids[i].startswith(":")),
            len(self.lane_ids) - 1,
        )
        return first, after


class AgentPlanner:
    """State and decisions of one mission vehicle."""

    def __init__(self) -> None:
        self.target_lane: int | None = None
        self.stopped_at_line = False
        self.committed_junction = False
        self.last_road: str | None = None
        # The last target path that followed the route: inside a junction the observed path can
        # be a different connection (overlapping internal lanes), so we keep to this one.
        self.memory: Path | None = None
        self.slow_for: float | None = None  # [m/s] dropping back to find a gap
        self.leaving_ending_lane = False  # change lanes briskly: the current one ends
        self.must_merge = False  # on an on-ramp's acceleration lane
        self.merge_road: str | None = None
        self.last_limit: float | None = None  # [m/s] speed limit of the last normal road
        self.lat_rate = 0.0  # [m/s] lateral speed (left positive) of the last pose

    def act(self, obs: dict) -> list[float]:
        ego = obs["ego_vehicle_state"]
        x, y = float(ego["position"][0]), float(ego["position"][1])
        heading, speed = float(ego["heading"]), float(ego["speed"])
        length, width = float(ego["bounding_box"][0]), float(ego["bounding_box"][1])
        route = tuple(ego["mission"]["route"])
        paths = []
        for waypoints in obs.get("waypoint_paths") or []:
            lane_ids = [w["lane_id"] for w in waypoints]
            if len(waypoints) >= 2 and on_route(lane_ids, route):
                paths.append(Path(waypoints, lane_ids))
        if not paths:
            if self.memory is None or self.memory.project(x, y)[0] > self.memory.length - 1.0:
                return self._brake(x, y, heading, speed)
            paths = [self.memory]
        goal = ego["mission"]["goal"]["position"]
        gx, gy = float(goal[0]), float(goal[1])
        others = obs.get("neighborhood_vehicle_states") or []
        points = np.array([[x, y], [gx, gy], *(o["position"][:2] for o in others)], dtype=float)
        for path in paths:
            path.project_step(points, others)
        road = ego.get("road_id")
        if road != self.last_road:
            self.last_road = road
            self.target_lane = None
            if not str(road).startswith(":"):
                self.stopped_at_line = False
                self.committed_junction = False
        current = min(paths, key=lambda p: abs(p.project(x, y)[1]))
        self._track_merge(str(road), current, paths)
        target = self._choose_lane(paths, current, x, y, gx, gy, speed, length, others)
        self.leaving_ending_lane = target is not current and current.ends

        # Speed: IDM on the corridors of the current and target lanes.
        v_desired = self._desired_speed(current, target, x, y)
        gap, lead_speed = self._lead(current, x, y, length, width, others)
        if target is not current:
            g2, v2 = self._lead(target, x, y, length, width, others)
            if g2 < gap:
                gap, lead_speed = g2, v2
        end_gap = self._lane_end_gap(current, target, x, y, length, gx, gy)
        if end_gap < gap:
            gap, lead_speed = end_gap, 0.0
        stop_gap = self._junction_gap(current, x, y, speed, length, others)
        if stop_gap is not None and stop_gap < gap:
            gap, lead_speed = stop_gap, 0.0
        accel = idm(speed, v_desired, gap, lead_speed)
        if self.slow_for is not None:
            accel = min(accel, max((self.slow_for - speed) / 1.5, -B_COMF))
        if target is not self.memory:
            self.memory = target
        return self._pose(target, x, y, heading, speed, accel)

    # --- lanes -----------------------------------------------------------------------------

    def _track_merge(self, road: str, current: Path, paths: list[Path]) -> None:
        """Entering the rightmost lane of a faster multi-lane road from a slower road is an
        on-ramp: that lane (acceleration lane, or shoulder further on) is left for the next one."""
        if road.startswith(":"):
            return
        limit = float(current.limits[0])
        if road != self.merge_road:
            entered_faster = self.last_limit is not None and limit > self.last_limit + 0.5
            self.must_merge = entered_faster and current.lane_index == 0 and len(paths) > 1
            self.merge_road = road
        if current.lane_index > 0:
            self.must_merge = False
        self.last_limit = limit

    def _choose_lane(self, paths, current, x, y, gx, gy, speed, length, others) -> Path:
        self.slow_for = None
        usable = [p for p in paths if p.width >= SHOULDER_WIDTH] or paths
        goal_dist = math.hypot(gx - x, gy - y)
        offsets = {id(p): p.goal_offset(gx, gy) for p in usable}
        goal_path = min(usable, key=lambda p: offsets[id(p)])
        wanted = goal_path
        ending = [p for p in usable if p.ends and goal_dist > p.length + 5.0]
        if goal_dist > GOAL_LANE_DISTANCE and current in usable and current not in ending:
            # Overtaking: prefer an adjacent lane whose traffic ahead is faster.
            def score(p: Path) -> float:
                gap, v = self._lead(p, x, y, length, 1.8, others)
                value = min(v if gap < 60.0 else 99.0, 30.0)
                return value + (2.0 if p is current else 0.0) + (2.5 if p is goal_path else 0.0)

            near = [p for p in usable if abs(p.lane_index - current.lane_index) <= 1]
            near = [p for p in near if p not in ending]
            wanted = max(near, key=score) if near else goal_path
        if self.must_merge and goal_dist > current.length:
            wanted = next((p for p in usable if p.lane_index == current.lane_index + 1), wanted)
        if wanted.lane_index == current.lane_index:
            self.target_lane = current.lane_index
            return current
        step = 1 if wanted.lane_index > current.lane_index else -1
        nxt = next((p for p in paths if p.lane_index == current.lane_index + step), None)
        if nxt is None:
            return current
        blocker = self._blocker(nxt, x, y, speed, length, others)
        if blocker is not None and self.target_lane == nxt.lane_index:
            # A change under way goes on once we are across the line; before that, a vehicle
            # that appeared in the gap (or closed it) makes us return to our lane.
            across = abs(nxt.project(x, y)[1]) < 0.5 * nxt.width
            if (across and blocker[0] < 0.0) or abs(blocker[0]) > length + 2.0:
                blocker = None
        if blocker is None:
            self.target_lane = nxt.lane_index
            return nxt
        # A lane change we want is blocked: drop back behind a vehicle ahead of us or faster
        # from behind, keep going past one behind us (two agents level with each other and
        # wanting to swap lanes then split instead of both dropping back side by side).
        offset, blocker_speed = blocker
        drop_back = offset > 0.0 or blocker_speed > speed + 0.5
        if not drop_back and wanted is goal_path:
            # Pulling ahead of a slower vehicle takes too long if the goal comes first.
            to_clear = rear_gap_needed(blocker_speed, speed) + length - offset
            gain = max(float(nxt.limits[0]) - blocker_speed, 0.1)
            drop_back = to_clear / gain > goal_dist / max(speed, 1.0)
        if drop_back:
            self.slow_for = max(min(blocker_speed, speed) - 4.0, 2.0)
        return current

    def _blocker(self, path: Path, x, y, speed, length, others) -> tuple[float, float] | None:
        """(longitudinal offset [m], speed [m/s]) of a vehicle in ``path``'s lane that leaves too
        small a gap ahead of or behind us for a lane change, or None when the change is safe."""
        s0, _ = path.project(x, y)
        for o, (s, lat) in zip(others, path.project_vehicles(others), strict=True):
            if abs(lat) > path.width * 0.5 + 0.4:
                continue
            half = 0.5 * (length + o["bounding_box"][0])
            v = o["speed"]
            if s >= s0:
                if s - s0 - half < max(4.0, 0.4 * speed + (speed - v) * 1.5):
                    return s - s0, v
            elif s0 - s - half < rear_gap_needed(v, speed):
                return s - s0, v
        return None

    # --- speed -----------------------------------------------------------------------------

    def _desired_speed(self, current: Path, target: Path, x, y) -> float:
        s0, _ = target.project(x, y)
        ahead = (target.s >= s0) & (target.s <= s0 + 40.0)
        limit = float(target.limits[ahead].min()) if ahead.any() else float(target.limits[0])
        v = limit
        # Curvature from chord directions 5 m apart (waypoint headings step at shape corners and
        # are unreliable on tiny junction lanes).
        xy, n = target.xy, len(target.xy)
        if n > 12:
            chord = xy[5:] - xy[:-5]
            # math.atan2, not np.arctan2: numpy's differs in the last bit on AVX-512 CPUs
            direction = np.array(list(map(math.atan2, chord[:, 1].tolist(), chord[:, 0].tolist())))
            # np.unwrap changes nothing unless the direction jumps across +-pi, and it is slow.
            if (np.abs(np.diff(direction)) >= math.pi).any():
                direction = np.unwrap(direction)
            ds = np.maximum(target.s[10:] - target.s[:-10], 1e-6)
            kappa = np.abs(direction[5:] - direction[:-5]) / ds
            s_mid = target.s[5:-5]
            curve = (s_mid >= s0) & (kappa >= 1e-3)
            if curve.any():
                # Slow enough now to reach each curve's speed with comfortable braking. Only the
                # lowest bound counts: those within rounding of the lowest are computed exactly.
                k, s = kappa[curve], s_mid[curve]
                bound = np.sqrt(A_LAT / k + 2 * B_COMF * np.maximum(s - s0, 0.0))
                lowest = bound <= bound.min() * (1.0 + 1e-9)
                for k_i, s_i in zip(k[lowest], s[lowest], strict=True):
                    v_curve = math.sqrt(A_LAT / k_i)
                    v = min(v, math.sqrt(v_curve**2 + 2 * B_COMF * max(s_i - s0, 0.0)))
        return max(v, 0.0)

    def _lead(self, path: Path, x, y, length, width, others) -> tuple[float, float]:
        """(gap [m], speed [m/s]) of the nearest vehicle ahead within the lane corridor."""
        s0, _ = path.project(x, y)
        best = (1e9, 30.0)
        for o, (s, lat) in zip(others, path.project_vehicles(others), strict=True):
            if s <= s0 or s - s0 > 120.0:
                continue
            if abs(lat) > 0.5 * (width + o["bounding_box"][1]) + 0.3:
                continue
            gap = s - s0 - 0.5 * (length + o["bounding_box"][0])
            # Oncoming (crossing in a junction) traffic has a negative speed along our path.
            along = o["speed"] * math.cos(wrap(o["heading"] - path.point(s)[2]))
            if gap < best[0]:
                best = (gap, max(along, -15.0))
        return best

    def _lane_end_gap(self, current: Path, target: Path, x, y, length, gx, gy) -> float:
        """Distance to the end of a lane that stops short of the goal (acceleration lane)."""
        s0, _ = current.project(x, y)
        goal_s, _ = current.project(gx, gy)
        if current.ends and goal_s > current.length + 2.0 and target is current:
            return current.length - s0 - 0.5 * length - 1.0
        return 1e9

    def _junction_gap(self, path: Path, x, y, speed, length, others) -> float | None:
        """Distance to the stop line while we must stop or yield there, else None."""
        span = path.junction_span()
        if self.committed_junction or span is None:
            if span is not None and span[0] == 0:
                self.committed_junction = True
            return None
        first, after = span
        if first == 0:
            self.committed_junction = True
            return None
        s_line = path.s[first]
        s0, _ = path.project(x, y)
        dist = s_line - s0 - 0.5 * length
        if dist > 60.0:
            return None
        turn = abs(wrap(path.direction(after + 4) - path.direction(first - 6))) > 0.5
        minor = path.limits[after] > path.limits[max(first - 1, 0)] + 0.5
        if not (turn or minor):
            return None
        if turn and not self.stopped_at_line:
            if dist < 3.0 and speed < STOP_SPEED:
                self.stopped_at_line = True
            else:
                return max(dist, 0.0)
        if self._conflict(path, first, after, s0, speed, length, others):
            return max(dist, 0.0)
        if dist < 2.0:
            self.committed_junction = True
        return None

    def _conflict(self, path: Path, first, after, s0, speed, length, others) -> bool:
        """Will another vehicle be near a point of our path through the junction while we pass
        it? Others move at constant velocity; we accelerate from our speed at A_MAX."""
        end = min(after + 12, len(path.s) - 1)
        zone_s = path.s[max(first - 2, 0) : end + 1]
        zone = path.xy[max(first - 2, 0) : end + 1]
        d = np.maximum(zone_s - s0, 0.0)
        v_top = 10.0
        t_reach = np.where(
            speed + np.sqrt(np.maximum(speed**2 + 2 * A_MAX * d, 0)) > 0,
            (np.sqrt(speed**2 + 2 * A_MAX * d) - speed) / A_MAX,
            0.0,
        )
        t_reach = np.minimum(t_reach, d / v_top + v_top / (2 * A_MAX))
        t_in = t_reach - 1.0
        t_out = t_reach + (length + 2.0) / max(speed, 2.0) + 1.0
        times = np.arange(0.0, 9.0, 0.25)
        ego_h = path.heading[0]
        for o in others:
            ox, oy, oh, ov = o["position"][0], o["position"][1], o["heading"], o["speed"]
            rel = math.cos(ego_h) * (ox - path.xy[0, 0]) + math.sin(ego_h) * (oy - path.xy[0, 1])
            if abs(wrap(oh - ego_h)) < 0.5 and rel < 0:
                continue  # following us
            if ov >= 1.0:
                travel = ov * times
            elif str(o.get("lane_id", "")).startswith(":"):
                travel = 0.5 * 2.0 * times**2  # waiting inside the junction: about to go
            else:
                travel = 0.0 * times  # standing at its line or queued: it gives way
            px = ox + math.cos(oh) * travel
            py = oy + math.sin(oh) * travel
            dist = np.hypot(px[:, None] - zone[None, :, 0], py[:, None] - zone[None, :, 1])
            near = dist < CONFLICT_RADIUS
            ti, zi = np.nonzero(near)
            if len(ti) and np.any((times[ti] >= t_in[zi]) & (times[ti] <= t_out[zi])):
                return True
        return False

    # --- action ----------------------------------------------------------------------------

    def _pose(self, target: Path, x, y, heading, speed, accel) -> list[float]:
        v = max(0.0, speed + accel * DT)
        s0, lat = target.project(x, y)
        ds = 0.5 * (speed + v) * DT
        if ds < 1e-3:
            return [x, y, heading, DT]
        lateral_speed = LAT_SPEED * max(1.0, v / 10.0) * (2.0 if self.leaving_ending_lane else 1.0)
        # Towards the target lane's centre, slowing down to arrive with no lateral speed; lanes
        # are parallel, so the rate carries over when the target lane changes.
        wanted = -math.copysign(min(lateral_speed, math.sqrt(2.0 * LAT_ACCEL * abs(lat))), lat)
        self.lat_rate += clip(wanted - self.lat_rate, -LAT_ACCEL * DT, LAT_ACCEL * DT)
        new_lat = lat + self.lat_rate * DT
        if new_lat * lat <= 0.0:  # reached the centre
            new_lat, self.lat_rate = 0.0, 0.0
        px, py, ph = target.point(s0 + ds)
        nx, ny = -math.sin(ph), math.cos(ph)
        tx, ty = px + nx * new_lat, py + ny * new_lat
        h = math.atan2(ty - y, tx - x) if math.hypot(tx - x, ty - y) > 0.05 else ph
        return [tx, ty, wrap(h), DT]

    def _brake(self, x, y, heading, speed) -> list[float]:
        ds = max(0.0, speed - B_MAX * DT) * DT
        return [x + ds * math.cos(heading), y + ds * math.sin(heading), heading, DT]


def clip(value: float, low: float, high: float) -> float:
    """np.clip of one number, without its per-call cost."""
    return float(min(max(value, low), high))


def rear_gap_needed(v_rear: float, v: float) -> float:
    """Gap [m] a lane change must leave to a vehicle at ``v_rear`` [m/s] behind us at ``v``."""
    return max(4.0, 0.4 * v_rear + (v_rear - v) * 2.5)


def idm(v: float, v0: float, gap: float, v_lead: float) -> float:
    """Intelligent Driver Model acceleration [m/s^2], clipped to [-B_MAX, A_MAX]."""
    v0 = max(v0, 0.1)
    free = 1.0 - (v / v0) ** 4
    if gap >= 1e8:
        return clip(A_MAX * free, -B_MAX, A_MAX)
    s_star = S0 + max(0.0, v * HEADWAY + v * (v - v_lead) / (2 * math.sqrt(A_MAX * B_COMF)))
    a = A_MAX * (free - (s_star / max(gap, 0.1)) ** 2)
    return clip(a, -B_MAX, A_MAX)


class Policy:
    def __init__(self) -> None:
        self.agents: dict[str, AgentPlanner] = {}

    def reset(self) -> None:
        self.agents = {}

    def act(self, obs: dict[str, dict]) -> dict[str, list[float]]:
        return {
            agent_id: self.agents.setdefault(agent_id, AgentPlanner()).act(agent_obs)
            for agent_id, agent_obs in obs.items()
        }
