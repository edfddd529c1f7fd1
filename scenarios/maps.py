"""Map templates: road layouts as plain SUMO node/edge/connection XML, built with netconvert.

Every template is a pure function of its parameters, so a built ``.net.xml`` is a pure function of
the template name (netconvert is deterministic; its date/config header comment is stripped). Built
maps are cached on disk by the hash of the netconvert inputs, so a suite build runs netconvert once
per template.

Conventions (documented in docs/scenarios.md): right-hand traffic, metres, lane 0 is the
rightmost lane; a *shoulder* is a lane whose ``allow`` list is exactly ``emergency``; every lane has
a speed limit.
"""

from __future__ import annotations

import hashlib
import math
import re
import subprocess
import tempfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

from arena.child_env import HOST_TOOL_VARIABLES, child_environment
from arena.errors import ArenaError
from arena.files import write_atomically

LANE_WIDTH = 3.2  # [m]
SHOULDER_WIDTH = 2.5  # [m]
HIGHWAY_SPEED = 22.22  # [m/s] 80 km/h
RAMP_SPEED = 16.67  # [m/s] 60 km/h
URBAN_SPEED = 13.89  # [m/s] 50 km/h
MINOR_SPEED = 11.11  # [m/s] 40 km/h

# [m] shape point spacing of curved roads: a polyline vertex turns the lane by spacing / radius,
# and a vehicle following lane points feels each turn as a heading step (2 m on a 400 m radius:
# 0.005 rad, less than one step's worth of smooth turning at highway speed).
CURVE_SHAPE_SPACING = 2

Point = tuple[float, float]


@dataclass(frozen=True)
class Edge:
    id: str
    start: str
    end: str
    lanes: int
    speed: float  # [m/s]
    priority: int = 1
    shape: tuple[Point, ...] = ()  # inner points only; the node positions are added
    shoulder: bool = False  # lane 0 is a shoulder
    # The shape's last point is the edge's end, beside its node: a ramp ends level with the
    # lane it joins instead of bending across the main road's lanes to the node.
    ends_beside_node: bool = False


@dataclass(frozen=True)
class Template:
    """A road layout before netconvert: nodes, edges, explicit lane connections."""

    nodes: dict[str, Point]
    edges: tuple[Edge, ...]
    connections: tuple[tuple[str, str, int, int], ...] = ()  # from, to, fromLane, toLane
    node_types: dict[str, str] = field(default_factory=dict)

    def transformed(self, fn: Callable[[Point], Point]) -> Template:
        return Template(
            nodes={k: fn(p) for k, p in self.nodes.items()},
            edges=tuple(
                Edge(**{**e.__dict__, "shape": tuple(fn(p) for p in e.shape)}) for e in self.edges
            ),
            connections=self.connections,
            node_types=self.node_types,
        )

    def to_xml(self) -> tuple[str, str, str]:
        """(nodes, edges, connections) plain XML documents."""
        nodes = ["<nodes>"]
        for nid, (x, y) in sorted(self.nodes.items()):
            kind = self.node_types.get(nid, "priority")
            nodes.append(f'  <node id="{nid}" x="{x:.3f}" y="{y:.3f}" type="{kind}"/>')
        nodes.append("</nodes>")
        edges = ["<edges>"]
        for e in self.edges:
            shape = ""
            if e.shape:
                end = [] if e.ends_beside_node else [self.nodes[e.end]]
                pts = [self.nodes[e.start], *e.shape, *end]
                shape = ' shape="' + " ".join(f"{x:.3f},{y:.3f}" for x, y in pts) + '"'
            edges.append(
                f'  <edge id="{e.id}" from="{e.start}" to="{e.end}" numLanes="{e.lanes}" '
                f'speed="{e.speed:.2f}" priority="{e.priority}" width="{LANE_WIDTH}"{shape}>'
            )
            for i in range(e.lanes):
                if e.shoulder and i == 0:
                    edges.append(
                        f'    <lane index="0" allow="emergency" width="{SHOULDER_WIDTH}" '
                        f'speed="{e.speed:.2f}"/>'
                    )
                else:
                    edges.append(f'    <lane index="{i}" speed="{e.speed:.2f}"/>')
            edges.append("  </edge>")
        edges.append("</edges>")
        cons = ["<connections>"]
        for src, dst, fl, tl in self.connections:
            cons.append(f'  <connection from="{src}" to="{dst}" fromLane="{fl}" toLane="{tl}"/>')
        cons.append("</connections>")
        return "\n".join(nodes) + "\n", "\n".join(edges) + "\n", "\n".join(cons) + "\n"


def _centreline(curved: bool, radius: float) -> Callable[..., Point]:
    """Point at arc length ``s`` [m] and left offset ``off`` [m] of a road starting at the origin
    heading +x: straight, or curving left on ``radius`` [m]."""

    def at(s: float, off: float = 0.0) -> Point:
        if not curved:
            return (s, off)
        a, r = s / radius, radius - off
        return (r * math.sin(a), radius - r * math.cos(a))

    return at


def _inner(at: Callable[..., Point], s0: float, s1: float, step: int) -> tuple[Point, ...]:
    """Shape points strictly between arc lengths ``s0`` and ``s1`` every ``step`` [m]."""
    return tuple(at(float(s)) for s in range(int(s0) + step, int(s1), step))


def _ramp(at: Callable[..., Point], start: Point, end: Point) -> tuple[Point, ...]:
    """Shape points after ``start`` up to ``end``, both (arc length, left offset) [m] along the
    road of ``at``: a smootherstep in offset, so the ramp leaves and joins parallel to the road
    with no step in curvature (a kinked ramp is a jerk spike for a vehicle following it)."""
    (s0, off0), (s1, off1) = start, end
    points = []
    for s in range(int(s0) + CURVE_SHAPE_SPACING, int(s1) + 1, CURVE_SHAPE_SPACING):
        u = (s - s0) / (s1 - s0)
        blend = u**3 * (10.0 - 15.0 * u + 6.0 * u * u)
        points.append(at(float(s), off0 + (off1 - off0) * blend))
    return tuple(points)


def highway(lanes: int, curved: bool = False) -> Template:
    """600 m two-edge highway (``in`` then ``out``); curved variants bend left on a 400 m radius."""
    at = _centreline(curved, 400.0)
    nodes = {"a": at(0.0), "b": at(300.0), "c": at(600.0)}
    shape = (
        (lambda s0, s1: _inner(at, s0, s1, CURVE_SHAPE_SPACING)) if curved else (lambda s0, s1: ())
    )
    edges = (
        Edge("in", "a", "b", lanes, HIGHWAY_SPEED, 3, shape(0, 300)),
        Edge("out", "b", "c", lanes, HIGHWAY_SPEED, 3, shape(300, 600)),
    )
    return Template(nodes, edges)


def merge(main_lanes: int, accel: float, shoulder: bool, curved: bool = False) -> Template:
    """A main road (``in`` -> ``merge`` -> ``out``) joined from the right by a one-lane ``ramp``.

    ``merge`` carries an acceleration lane (index 0) of length ``accel`` [m] that ends at its end
    (or continues as the shoulder of ``out`` when ``shoulder``)."""
    at = _centreline(curved, 700.0)
    b, c, d = 250.0, 250.0 + accel, 250.0 + accel + 300.0
    nodes = {"a": at(0.0), "b": at(b), "c": at(c), "d": at(d), "r": at(40.0, -70.0)}
    shape = (
        (lambda s0, s1: _inner(at, s0, s1, CURVE_SHAPE_SPACING)) if curved else (lambda s0, s1: ())
    )
    # Lanes lie right of their edge's line: the ramp's line ends where its lane is the
    # acceleration lane, right of the main road's lanes.
    ramp_shape = _ramp(at, (40.0, -70.0), (b, -main_lanes * LANE_WIDTH))
    out_lanes = main_lanes + (1 if shoulder else 0)
    edges = (
        Edge("in", "a", "b", main_lanes, HIGHWAY_SPEED, 3, shape(0, b)),
        Edge("ramp", "r", "b", 1, RAMP_SPEED, 1, ramp_shape, ends_beside_node=True),
        Edge("merge", "b", "c", main_lanes + 1, HIGHWAY_SPEED, 3, shape(b, c)),
        Edge("out", "c", "d", out_lanes, HIGHWAY_SPEED, 3, shape(c, d), shoulder=shoulder),
    )
    shift = 1 if shoulder else 0
    connections = [("in", "merge", i, i + 1) for i in range(main_lanes)]
    connections.append(("ramp", "merge", 0, 0))
    connections += [("merge", "out", i + 1, i + shift) for i in range(main_lanes)]
    if shoulder:
        connections.append(("merge", "out", 0, 0))
    return Template(nodes, edges, tuple(connections))


def t_intersection() -> Template:
    """Major road west-east (2 lanes each way, priority), one-lane minor road from the south with a
    stop sign (junction type ``priority_stop``: minor links get state ``s``)."""
    nodes = {"J": (0.0, 0.0), "W": (-250.0, 0.0), "E": (250.0, 0.0), "S": (0.0, -200.0)}
    edges = (
        Edge("w_in", "W", "J", 2, URBAN_SPEED, 3),
        Edge("w_out", "J", "W", 2, URBAN_SPEED, 3),
        Edge("e_in", "E", "J", 2, URBAN_SPEED, 3),
        Edge("e_out", "J", "E", 2, URBAN_SPEED, 3),
        Edge("s_in", "S", "J", 1, MINOR_SPEED, 1),
        Edge("s_out", "J", "S", 1, MINOR_SPEED, 1),
    )
    connections = (("s_in", "w_out", 0, 0), ("s_in", "w_out", 0, 1), ("s_in", "e_out", 0, 0))
    return Template(nodes, edges, connections, {"J": "priority_stop"})


def cross_intersection() -> Template:
    """Unsignalised cross: three-lane main road west-east with priority, one-lane minor road
    south-north crossing it at a skew (so mirrored variants differ from rotated ones)."""
    nodes = {
        "J": (0.0, 0.0),
        "W": (-250.0, 0.0),
        "E": (250.0, 0.0),
        "S": (-50.0, -190.0),
        "N": (50.0, 190.0),
    }
    edges = (
        Edge("w_in", "W", "J", 3, URBAN_SPEED, 3),
        Edge("w_out", "J", "W", 3, URBAN_SPEED, 3),
        Edge("e_in", "E", "J", 3, URBAN_SPEED, 3),
        Edge("e_out", "J", "E", 3, URBAN_SPEED, 3),
        Edge("s_in", "S", "J", 1, MINOR_SPEED, 1),
        Edge("s_out", "J", "S", 1, MINOR_SPEED, 1),
        Edge("n_in", "N", "J", 1, MINOR_SPEED, 1),
        Edge("n_out", "J", "N", 1, MINOR_SPEED, 1),
    )
    connections = []
    for src, left, right, straight in (
        ("s_in", "w_out", "e_out", "n_out"),
        ("n_in", "e_out", "w_out", "s_out"),
    ):
        connections += [(src, left, 0, i) for i in range(3)]
        connections += [(src, right, 0, i) for i in range(3)]
        connections.append((src, straight, 0, 0))
    return Template(nodes, edges, tuple(connections))


def urban() -> Template:
    """Mixed urban map: a two-lane avenue with an unsignalised cross junction and a stop-sign T
    junction 200 m apart."""
    nodes = {
        "W": (-200.0, 0.0),
        "J1": (0.0, 0.0),
        "J2": (200.0, 0.0),
        "E": (400.0, 0.0),
        "N1": (0.0, 180.0),
        "S1": (0.0, -180.0),
        "S2": (200.0, -180.0),
    }
    edges = []
    for a, b, lanes, speed, prio in (
        ("W", "J1", 2, URBAN_SPEED, 3),
        ("J1", "J2", 2, URBAN_SPEED, 3),
        ("J2", "E", 2, URBAN_SPEED, 3),
        ("N1", "J1", 1, MINOR_SPEED, 1),
        ("S1", "J1", 1, MINOR_SPEED, 1),
        ("S2", "J2", 1, MINOR_SPEED, 1),
    ):
        edges.append(Edge(f"{a}_{b}", a, b, lanes, speed, prio))
        edges.append(Edge(f"{b}_{a}", b, a, lanes, speed, prio))
    return Template(nodes, tuple(edges), (), {"J2": "priority_stop"})


def _rotate(deg: float) -> Callable[[Point], Point]:
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return lambda p: (c * p[0] - s * p[1], s * p[0] + c * p[1])


def _mirror(p: Point) -> Point:
    return (p[0], -p[1])


TEMPLATES: dict[str, Callable[[], Template]] = {
    "highway_2lane": lambda: highway(2),
    "highway_3lane": lambda: highway(3),
    "highway_4lane": lambda: highway(4),
    "highway_2lane_curve": lambda: highway(2, curved=True),
    "highway_3lane_curve": lambda: highway(3, curved=True),
    "highway_4lane_curve": lambda: highway(4, curved=True),
    "merge_2lane": lambda: merge(2, 160.0, shoulder=False),
    "merge_2lane_shoulder": lambda: merge(2, 160.0, shoulder=True),
    "merge_2lane_shoulder_short": lambda: merge(2, 70.0, shoulder=True),
    "merge_3lane_curve": lambda: merge(3, 160.0, shoulder=False, curved=True),
    "merge_3lane_shoulder": lambda: merge(3, 160.0, shoulder=True),
    "merge_3lane_shoulder_short": lambda: merge(3, 70.0, shoulder=True),
    "merge_4lane": lambda: merge(4, 160.0, shoulder=False),
    "t_intersection": t_intersection,
    "t_intersection_rotated": lambda: t_intersection().transformed(_rotate(90.0)),
    "cross": cross_intersection,
    "cross_rotated": lambda: cross_intersection().transformed(_rotate(90.0)),
    # Mirrored upside down: the minor road's south arm comes from the north and its skew flips;
    # traffic stays right-hand (netconvert lays lanes out from the edge directions), so a turn
    # onto the same edge changes side: generators pick turns by direction, not by edge name.
    "cross_upside": lambda: cross_intersection().transformed(_mirror),
    "cross_upside_rotated": lambda: (
        cross_intersection().transformed(_mirror).transformed(_rotate(90.0))
    ),
    "replay_highway": lambda: merge(5, 200.0, shoulder=False),
    "urban": urban,
}

_HEADER = re.compile(rb"<!-- generated on .*?-->\s*", re.DOTALL)
NETCONVERT_OPTIONS = (
    "--offset.disable-normalization",
    "true",
    "--no-turnarounds",
    "true",
    "--junctions.corner-detail",
    "5",
    "--default.lanewidth",
    str(LANE_WIDTH),
    # Centimetre coordinates (the default) make 2 m curve segments zig-zag by 0.005 rad.
    "--precision",
    "4",
)


class MapBuildError(ArenaError, RuntimeError):
    pass


def _tool_env() -> dict[str, str]:
    return child_environment(inherit=HOST_TOOL_VARIABLES)


@lru_cache(maxsize=1)
def netconvert_version() -> str:
    out = subprocess.run(
        ["netconvert", "--version"], capture_output=True, text=True, check=True, env=_tool_env()
    )
    return out.stdout.splitlines()[0].strip()


def build_map(name: str, cache_dir: Path) -> Path:
    """The ``.net.xml`` of template ``name``, built once into ``cache_dir`` and reused."""
    if name not in TEMPLATES:
        raise KeyError(f"unknown map template {name!r}; known: {', '.join(sorted(TEMPLATES))}")
    return convert_plain_xml(name, TEMPLATES[name]().to_xml(), NETCONVERT_OPTIONS, cache_dir)


def convert_plain_xml(
    name: str, documents: Sequence[str], options: Sequence[str], cache_dir: Path
) -> Path:
    """netconvert of plain XML ``documents`` (nodes, edges, connections) into
    ``cache_dir/<name>-<key>.net.xml``, keyed by the hash of every input, and reused."""
    key = hashlib.sha256(
        "\0".join([*documents, *options, netconvert_version()]).encode()
    ).hexdigest()[:16]
    target = Path(cache_dir) / f"{name}-{key}.net.xml"
    if target.exists():
        return target
    target.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        tmpdir = Path(tmp)
        for suffix, text in zip(("nod", "edg", "con"), documents, strict=True):
            (tmpdir / f"map.{suffix}.xml").write_text(text)
        cmd = ["netconvert", "-n", "map.nod.xml", "-e", "map.edg.xml", "-x", "map.con.xml"]
        cmd += ["-o", "map.net.xml", *options, "--no-warnings"]
        proc = subprocess.run(cmd, cwd=tmpdir, capture_output=True, text=True, env=_tool_env())
        if proc.returncode != 0:
            raise MapBuildError(f"netconvert failed for {name}: {proc.stderr.strip()}")
        data = _HEADER.sub(b"", (tmpdir / "map.net.xml").read_bytes(), count=1)
        write_atomically(target, data)
    return target
