"""One lane of the road network: its centreline as a polyline and the lane-frame maths on it."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

WAYPOINT_SPACING = 1.0  # [m] distance between consecutive waypoints along a lane


def wrap_angle(angle: float | np.ndarray) -> float | np.ndarray:
    """Wrap radians to (-pi, pi]."""
    return np.pi - np.mod(np.pi - angle, 2 * np.pi)


@dataclass(eq=False)
class Lane:
    """A SUMO lane. ``index`` 0 is the rightmost lane of its edge; internal lanes are the
    connections inside a junction. A lane that does not allow passenger cars is a shoulder."""

    id: str
    edge_id: str
    index: int
    centreline: np.ndarray  # (n, 2) [m], in driving direction
    width: float  # [m]
    speed_limit: float  # [m/s]
    is_internal: bool
    is_shoulder: bool
    successors: list[str] = field(default_factory=list)  # lane ids reachable at the lane's end

    def __post_init__(self) -> None:
        pts = np.asarray(self.centreline, dtype=np.float64)
        if len(pts) < 2 or np.allclose(pts[0], pts[-1]):
            # Zero-length internal lanes exist; give them a tiny extent so the maths stays finite.
            pts = np.array([pts[0], pts[0] + [1e-3, 0.0]])
        self.centreline = pts
        seg = np.diff(pts, axis=0)
        self.segment_lengths = np.hypot(seg[:, 0], seg[:, 1])  # (n-1,) [m]
        self.segment_headings = np.arctan2(seg[:, 1], seg[:, 0])  # (n-1,) [rad]
        self.cumulative_s = np.concatenate([[0.0], np.cumsum(self.segment_lengths)])  # (n,) [m]
        self.length = float(self.cumulative_s[-1])  # [m]

    def project(self, x: float, y: float) -> tuple[float, float, float]:
        """Lane coordinates of a point: (s [m] along the lane, t [m] signed lateral offset, left
        positive, heading [rad] of the lane at s)."""
        p0 = self.centreline[:-1]
        d = self.centreline[1:] - p0
        rel = np.array([x, y]) - p0
        u = np.clip((rel * d).sum(1) / np.maximum(self.segment_lengths**2, 1e-12), 0.0, 1.0)
        closest = p0 + d * u[:, None]
        dist2 = ((closest - [x, y]) ** 2).sum(1)
        i = int(np.argmin(dist2))
        return self._frame(i, float(u[i]), x, y)

    def _frame(self, i: int, u: float, x: float, y: float) -> tuple[float, float, float]:
        d = self.centreline[i + 1] - self.centreline[i]
        rel_x, rel_y = x - self.centreline[i][0], y - self.centreline[i][1]
        t = (d[0] * rel_y - d[1] * rel_x) / max(self.segment_lengths[i], 1e-12)
        s = float(self.cumulative_s[i] + u * self.segment_lengths[i])
        return s, float(t), float(self.segment_headings[i])

    def position_at(self, s: float | np.ndarray) -> np.ndarray:
        """Centreline point(s) at distance ``s`` [m] along the lane, (2,) or (m, 2)."""
        s = np.clip(s, 0.0, self.length)
        return np.stack(
            [
                np.interp(s, self.cumulative_s, self.centreline[:, 0]),
                np.interp(s, self.cumulative_s, self.centreline[:, 1]),
            ],
            axis=-1,
        )

    def heading_at(self, s: float | np.ndarray) -> float | np.ndarray:
        """Lane direction [rad] at distance ``s`` [m] along the lane."""
        i = np.clip(
            np.searchsorted(self.cumulative_s, s, side="right") - 1,
            0,
            len(self.segment_headings) - 1,
        )
        return self.segment_headings[i]

    @cached_property
    def waypoints(self) -> list[dict]:
        """Waypoint dicts every :data:`WAYPOINT_SPACING` along the lane, from s = 0.

        Built once per lane and shared by every observation: treat them as read-only.
        """
        s = np.arange(0.0, self.length, WAYPOINT_SPACING)
        pos = self.position_at(s)
        heading = self.heading_at(s)
        return [
            {
                "pos": [round(float(p[0]), 4), round(float(p[1]), 4)],
                "heading": float(h),
                "lane_id": self.id,
                "lane_index": self.index,
                "lane_width": self.width,
                "speed_limit": self.speed_limit,
                "lane_offset": float(si),
            }
            for p, h, si in zip(pos, heading, s, strict=True)
        ]

    @property
    def heading_start(self) -> float:
        return float(self.segment_headings[0])

    @property
    def heading_end(self) -> float:
        return float(self.segment_headings[-1])

    def __repr__(self) -> str:
        return f"Lane({self.id!r}, length={self.length:.1f}, width={self.width:.2f})"


def angle_between(a: float, b: float) -> float:
    """Absolute difference of two headings [rad], in [0, pi]."""
    return abs(math.remainder(a - b, 2 * math.pi))
