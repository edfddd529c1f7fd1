"""One agent's observation as fixed-shape numpy arrays: the Gymnasium observation space of
``learn/`` and what a policy with ``observation_format: arrays`` receives in its sandbox.

The observation (``docs/agent-interface.md``) has variable-length lists (neighbours, waypoints)
and strings (road and lane ids); fixed shapes need more. The arrays keep every numeric field
under its interface name, pad the lists to fixed sizes with a ``mask``, and leave out the ids
and ``done``. Rasters pass through. A scalar is an array of shape ``(1,)``, not ``()``: every
leaf has a dimension to check and batch along (Stable-Baselines3's ``check_env`` indexes each
box's out-of-bounds entries, which a 0-d array does not allow); the record's bytes are the same.

An :class:`ObservationLayout` places every array (a :class:`Leaf`) at a fixed offset in one flat
record, so an observation moves as raw bytes and is read back as views with no parsing: the
sandbox protocol sends the layout once and then one record per agent and step
(``docs/protocol.md``); learn's simulator process sends records to its environment.
"""

from __future__ import annotations

import functools
import math
import struct
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from itertools import chain
from operator import itemgetter

import numpy as np

from sim.interface import AgentInterface

EVENT_NAMES = (
    "collisions",
    "off_road",
    "off_route",
    "on_shoulder",
    "wrong_way",
    "not_moving",
    "reached_goal",
    "reached_max_episode_steps",
)
# (name, length) of the ego vectors; scalars have length 0 (an array of shape (1,)).
EGO_FIELDS = (
    ("position", 3),
    ("heading", 0),
    ("speed", 0),
    ("bounding_box", 3),
    ("steering", 0),
    ("yaw_rate", 0),
    ("lane_position", 2),
    ("linear_velocity", 3),
    ("angular_velocity", 3),
    ("linear_acceleration", 3),
    ("angular_acceleration", 3),
    ("linear_jerk", 3),
    ("angular_jerk", 3),
)
WAYPOINT_FIELDS = ("heading", "lane_width", "speed_limit", "lane_offset")
RASTER_NAMES = ("drivable_area_grid_map", "occupancy_grid_map", "top_down_rgb")
F32, I32, U8 = "<f4", "<i4", "|u1"
NEIGHBOURS = "neighborhood_vehicle_states"
PATHS = "waypoint_paths"
# [bytes] records are padded to this, so that every record of a frame starts aligned
RECORD_ALIGN = 8
_STRUCT_CODE = {F32: "f", I32: "i", U8: "B"}
_INF = math.inf


@dataclass(frozen=True)
class Leaf:
    """One array of the observation: where it sits in a record, and its Gymnasium bounds."""

    path: tuple[str, ...]  # keys from the top of the observation dict
    dtype: str  # numpy dtype string
    shape: tuple[int, ...]
    offset: int  # [bytes] from the record's start, a multiple of the item size
    low: float
    high: float

    @property
    def nbytes(self) -> int:
        return math.prod(self.shape) * np.dtype(self.dtype).itemsize


def _leaf_specs(
    interface: AgentInterface, n: int
) -> Iterator[tuple[tuple[str, ...], str, tuple[int, ...], float, float]]:
    """(path, dtype, shape, low, high) of every leaf, in record order. The leading scalars,
    events and ego fields form the record's fixed head (:class:`ObservationEncoder`)."""
    p, w = interface.max_waypoint_paths, interface.waypoints_per_path
    yield ("dt",), F32, (1,), 0.0, _INF
    yield ("step_count",), I32, (1,), 0, np.iinfo(np.int32).max
    yield ("elapsed_sim_time",), F32, (1,), 0.0, _INF
    yield ("distance_travelled",), F32, (1,), 0.0, _INF
    for name in EVENT_NAMES:
        # 0/1 as uint8 boxes: Discrete/MultiBinary would break vectorised batching of the
        # nested dict in some training libraries, a Box never does.
        yield ("events", name), U8, (1,), 0, 1
    ego = "ego_vehicle_state"
    for name, size in EGO_FIELDS:
        yield (ego, name), F32, (size or 1,), -_INF, _INF
    yield (ego, "lane_index"), I32, (1,), 0, 255
    yield (ego, "goal_position"), F32, (2,), -_INF, _INF
    yield (ego, "goal_radius"), F32, (1,), 0.0, _INF
    yield (NEIGHBOURS, "mask"), U8, (n,), 0, 1
    yield (NEIGHBOURS, "position"), F32, (n, 3), -_INF, _INF
    yield (NEIGHBOURS, "heading"), F32, (n,), -_INF, _INF
    yield (NEIGHBOURS, "speed"), F32, (n,), -_INF, _INF
    yield (NEIGHBOURS, "bounding_box"), F32, (n, 3), 0.0, _INF
    yield (NEIGHBOURS, "lane_index"), I32, (n,), 0, 255
    yield (PATHS, "mask"), U8, (p, w), 0, 1
    yield (PATHS, "pos"), F32, (p, w, 2), -_INF, _INF
    yield (PATHS, "lane_index"), I32, (p, w), 0, 255
    for name in WAYPOINT_FIELDS:
        yield (PATHS, name), F32, (p, w), -_INF, _INF
    px = interface.img_pixels
    for name in RASTER_NAMES:
        if getattr(interface, name):
            yield (name,), U8, (px, px, 3) if name == "top_down_rgb" else (px, px), 0, 255


class ObservationLayout:
    """Where each array of one agent's observation sits in its record, for an interface's
    ``max_waypoint_paths``, ``waypoints_per_path``, rasters and ``max_neighbours`` neighbour
    slots (the nearest kept: the simulator lists them nearest first)."""

    def __init__(self, interface: AgentInterface) -> None:
        self.interface = interface
        self.max_neighbours = interface.max_neighbours
        leaves, offset = [], 0
        for path, dtype, shape, low, high in _leaf_specs(interface, self.max_neighbours):
            offset = _aligned(offset, np.dtype(dtype).itemsize)
            leaves.append(Leaf(path, dtype, shape, offset, low, high))
            offset += leaves[-1].nbytes
        self.leaves: tuple[Leaf, ...] = tuple(leaves)
        self.size = _aligned(offset, RECORD_ALIGN)  # [bytes] of one record

    def leaf(self, *path: str) -> Leaf:
        return next(leaf for leaf in self.leaves if leaf.path == path)

    def describe(self) -> dict:
        """The layout as plain values, for a reader without this module (the sandbox runner)."""
        return {
            "size": self.size,
            "leaves": [[list(f.path), f.dtype, list(f.shape), f.offset] for f in self.leaves],
        }

    def arrays(self, record: bytearray | memoryview) -> dict:
        """The observation dict over ``record``: its arrays are views of it."""
        obs: dict = {}
        for leaf in self.leaves:
            node = obs
            for key in leaf.path[:-1]:
                node = node.setdefault(key, {})
            node[leaf.path[-1]] = np.ndarray(leaf.shape, leaf.dtype, record, leaf.offset)
        return obs


def _aligned(offset: int, alignment: int) -> int:
    return -(-offset // alignment) * alignment


@functools.cache
def _structs(code: str, count: int) -> struct.Struct:
    return struct.Struct(f"<{count}{code}")


class ObservationEncoder:
    """Writes observations into records of one layout, fast enough for every step in front of
    the sandbox protocol (about 25 µs for 4 x 50 waypoints and 16 neighbours, where building
    the ~40 arrays one by one took about 90 µs). Use one encoder per agent.

    The head (scalars, events, ego) is one ``struct`` call, the neighbours one per field, the
    waypoints one gather of each field over all paths and one numpy assignment per array
    (waypoints are built afresh for each observation, as paths start level with the vehicle).
    """

    def __init__(self, layout: ObservationLayout) -> None:
        self.layout = layout
        leaves = layout.leaves
        self._head = head_struct(layout)
        mask = layout.leaf(NEIGHBOURS, "mask")
        self._neighbours_at = mask.offset
        neighbour_end = layout.leaf(NEIGHBOURS, "lane_index")
        self._neighbour_zeros = bytes(neighbour_end.offset + neighbour_end.nbytes - mask.offset)
        self._neighbour_offsets = [
            layout.leaf(NEIGHBOURS, name).offset
            for name in ("position", "heading", "speed", "bounding_box", "lane_index")
        ]
        self._rasters = [f for f in leaves if f.path[0] in RASTER_NAMES]
        interface = layout.interface
        self._paths, self._per_path = interface.max_waypoint_paths, interface.waypoints_per_path
        flat = self._paths * self._per_path
        heading = layout.leaf(PATHS, WAYPOINT_FIELDS[0])
        # (view shape, dtype, offset); the four per-waypoint floats lie back to back, one
        # (4, flat) block.
        self._path_views_at = [
            ((flat,), U8, layout.leaf(PATHS, "mask").offset),
            ((flat, 2), F32, layout.leaf(PATHS, "pos").offset),
            ((flat,), I32, layout.leaf(PATHS, "lane_index").offset),
            ((len(WAYPOINT_FIELDS), flat), F32, heading.offset),
        ]
        last = layout.leaf(PATHS, WAYPOINT_FIELDS[-1])
        assert last.offset == heading.offset + (len(WAYPOINT_FIELDS) - 1) * heading.nbytes

    def encode(self, obs: dict) -> dict:
        """``obs`` (the agent-interface dict) as fresh arrays, writable, sharing one buffer."""
        record = bytearray(self.layout.size)
        self.write(obs, record)
        return self.layout.arrays(record)

    def write(self, obs: dict, record: bytearray) -> None:
        """Encode ``obs`` into ``record`` (``layout.size`` bytes; every byte is rewritten)."""
        self._head.pack_into(record, 0, *_head_values(obs))
        self._write_neighbours(obs[NEIGHBOURS], record)
        self._write_waypoints(obs[PATHS], record)
        for leaf in self._rasters:
            raster = np.asarray(obs[leaf.path[0]])
            if raster.shape != leaf.shape:
                raise ValueError(f"{leaf.path[0]}: shape {raster.shape}, expected {leaf.shape}")
            np.ndarray(leaf.shape, leaf.dtype, record, leaf.offset)[...] = raster

    def _write_neighbours(self, neighbours: list[dict], record: bytearray) -> None:
        at = self._neighbours_at
        record[at : at + len(self._neighbour_zeros)] = self._neighbour_zeros
        others = neighbours[: self.layout.max_neighbours]
        k = len(others)
        if not k:
            return
        record[at : at + k] = b"\x01" * k
        position, heading, speed, box, lane = zip(*map(_NEIGHBOUR_FIELDS, others), strict=True)
        pos_at, heading_at, speed_at, box_at, lane_at = self._neighbour_offsets
        triple, single = _structs("f", 3 * k), _structs("f", k)
        triple.pack_into(record, pos_at, *chain.from_iterable(position))
        single.pack_into(record, heading_at, *heading)
        single.pack_into(record, speed_at, *speed)
        triple.pack_into(record, box_at, *chain.from_iterable(box))
        _structs("i", k).pack_into(record, lane_at, *lane)

    def _write_waypoints(self, paths: list[list[dict]], record: bytearray) -> None:
        w = self._per_path
        slots: list[int] = []  # where each kept waypoint goes among the paths x w slots
        points: list[dict] = []
        for i, path in enumerate(paths[: self._paths]):
            path = path[:w]
            slots += range(i * w, i * w + len(path))
            points += path
        mask, pos, lane, floats = (
            np.ndarray(shape, dtype, record, offset) for shape, dtype, offset in self._path_views_at
        )
        for view in (mask, pos, lane, floats):  # zeros pad short and missing paths
            view.fill(0)
        if not points:
            return
        # np.fromiter over flat floats: several times faster than np.array on nested lists or
        # tuples; float64 then float32 rounds as a direct conversion does.
        n, fields = len(points), len(WAYPOINT_FIELDS)
        at = np.array(slots, np.intp)
        mask[at] = 1
        xy = chain.from_iterable(wp["pos"] for wp in points)
        pos[at] = np.fromiter(xy, np.float64, 2 * n).reshape(n, 2)
        lane[at] = [wp["lane_index"] for wp in points]
        values = chain.from_iterable(map(_WAYPOINT_FLOATS, points))
        floats[:, at] = np.fromiter(values, np.float64, fields * n).reshape(n, fields).T


_WAYPOINT_FLOATS = itemgetter(*WAYPOINT_FIELDS)
_NEIGHBOUR_FIELDS = itemgetter("position", "heading", "speed", "bounding_box", "lane_index")
_EVENTS = itemgetter(*EVENT_NAMES)


def head_leaves(layout: ObservationLayout) -> tuple[Leaf, ...]:
    """The head's leaves, in record order: those before the neighbours (the scalars, the
    events, the ego's fields, its lane index and the goal)."""
    first_variable = next(i for i, f in enumerate(layout.leaves) if f.path[0] == NEIGHBOURS)
    return layout.leaves[:first_variable]


def head_struct(layout: ObservationLayout) -> struct.Struct:
    """One struct for the :func:`head_leaves`: events pack any value's truth ('?'), as
    ``bool``."""
    parts, at = ["<"], 0
    for leaf in head_leaves(layout):
        parts.append("x" * (leaf.offset - at))
        code = "?" if leaf.path[0] == "events" else _STRUCT_CODE[leaf.dtype]
        parts.append(f"{math.prod(leaf.shape)}{code}")
        at = leaf.offset + leaf.nbytes
    return struct.Struct("".join(parts))


def _head_values(obs: dict) -> list:
    """The head's values in leaf order (:func:`_leaf_specs`)."""
    ego = obs["ego_vehicle_state"]
    goal = ego["mission"]["goal"]
    return head_values(
        (obs["dt"], obs["step_count"], obs["elapsed_sim_time"], obs["distance_travelled"]),
        _EVENTS(obs["events"]),
        [ego[name] for name, _ in EGO_FIELDS],
        ego["lane_index"],
        goal["position"],
        goal["radius"],
    )


def head_values(
    scalars: tuple[float, int, float, float],
    events: Iterable,
    ego: list,
    lane_index: int,
    goal_position: Iterable[float],
    goal_radius: float,
) -> list:
    """The head's values in leaf order (:func:`_leaf_specs`): ``scalars`` dt, step count,
    elapsed time and distance travelled, ``events`` in :data:`EVENT_NAMES` order and ``ego``
    in :data:`EGO_FIELDS` order (vectors as sequences)."""
    values = [*scalars, *events]
    for (_, size), value in zip(EGO_FIELDS, ego, strict=True):
        if size:
            values += value
        else:
            values.append(value)
    values.append(lane_index)
    values += goal_position
    values.append(goal_radius)
    return values
