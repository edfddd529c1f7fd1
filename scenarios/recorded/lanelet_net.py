"""CommonRoad lanelets -> a SUMO network, through plain node/edge/connection XML and netconvert.

Why not ``commonroad-scenario-designer``: its converter pulls in a GUI stack and a pinned
``commonroad-io`` that cannot open the 2018b files, and it re-derives lanes from its own graph;
the lanelet boundaries already say everything a SUMO lane needs, so we hand them to the same
netconvert (and options) that builds our own maps.

- Lanelets that are same-direction neighbours (``adjacentLeft/Right drivingDir="same"``) and start
  and end side by side become the lanes of one edge, rightmost = lane 0; any other lanelet is an
  edge of its own. Edge ids are ``cr<lanelet ids right to left>``.
- Every lane keeps its lanelet's centre line as a custom lane shape, its mean width and its speed
  limit, so the built lanes lie where the recorded vehicles drove, in their direction.
- Nodes are where lanelets meet: a lanelet's end and its successors' starts are one node, placed
  at their mean. Connections follow the lanelet successors exactly; netconvert computes the
  junction areas (internal lanes and junction shapes) from them.
- Coordinates are kept as they are (no offset normalisation), so trajectories need no shift.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np

from scenarios.maps import NETCONVERT_OPTIONS, convert_plain_xml
from scenarios.recorded.commonroad import Lanelet

SIDE_BY_SIDE_M = 1.0  # [m] neighbours whose ends are farther apart than this are separate edges
LANELET_NET_OPTIONS = ("--geometry.remove", "false")


class _Nodes:
    """Union-find over lanelet ends: key (lanelet id, 0 = start / 1 = end)."""

    def __init__(self) -> None:
        self.parent: dict[tuple[int, int], tuple[int, int]] = {}

    def find(self, key: tuple[int, int]) -> tuple[int, int]:
        self.parent.setdefault(key, key)
        while self.parent[key] != key:
            self.parent[key] = self.parent[self.parent[key]]
            key = self.parent[key]
        return key

    def union(self, a: tuple[int, int], b: tuple[int, int]) -> None:
        self.parent[self.find(a)] = self.find(b)


def _lanes_right_to_left(lanelets: dict[int, Lanelet]) -> list[list[Lanelet]]:
    """Groups of same-direction neighbours that start and end side by side, rightmost first."""
    groups, seen = [], set()
    for lid in sorted(lanelets):
        if lid in seen:
            continue
        right, walked = lanelets[lid], {lid}
        while (
            right.adjacent_right in lanelets
            and right.adjacent_right not in walked  # a file whose neighbours form a loop
            and _side_by_side(lanelets[right.adjacent_right], right)
        ):
            right = lanelets[right.adjacent_right]
            walked.add(right.id)
        group = [right]
        while group[-1].adjacent_left in lanelets and lanelets[group[-1].adjacent_left].id not in {
            g.id for g in group
        }:
            left = lanelets[group[-1].adjacent_left]
            if not _side_by_side(group[-1], left):
                break
            group.append(left)
        # Neighbour references that disagree (A's right is B but B's left is not A, or a group
        # overlapping one already made): keep the lanelet an edge of its own.
        if lid not in {g.id for g in group} or any(g.id in seen for g in group):
            group = [lanelets[lid]]
        seen.update(g.id for g in group)
        groups.append(group)
    return groups


def _side_by_side(right: Lanelet, left: Lanelet) -> bool:
    return bool(
        np.hypot(*(right.left[0] - left.right[0])) < SIDE_BY_SIDE_M
        and np.hypot(*(right.left[-1] - left.right[-1])) < SIDE_BY_SIDE_M
    )


def edge_id(group: Sequence[Lanelet]) -> str:
    return "cr" + "_".join(str(g.id) for g in group)


def _shape(points: np.ndarray) -> str:
    return " ".join(f"{x:.3f},{y:.3f}" for x, y in points)


def plain_xml(lanelets: Sequence[Lanelet]) -> tuple[str, str, str]:
    """(nodes, edges, connections) plain XML documents for netconvert."""
    by_id = {ln.id: ln for ln in lanelets}
    groups = _lanes_right_to_left(by_id)
    lane_of = {ln.id: (edge_id(g), i) for g in groups for i, ln in enumerate(g)}
    nodes = _Nodes()
    for g in groups:
        for ln in g[1:]:
            nodes.union((ln.id, 0), (g[0].id, 0))
            nodes.union((ln.id, 1), (g[0].id, 1))
    for ln in lanelets:
        for succ in ln.successors:
            if succ in by_id:
                nodes.union((ln.id, 1), (succ, 0))
    members: dict[tuple[int, int], list[np.ndarray]] = {}
    for ln in lanelets:
        members.setdefault(nodes.find((ln.id, 0)), []).append(ln.centre[0])
        members.setdefault(nodes.find((ln.id, 1)), []).append(ln.centre[-1])
    name = {root: f"n{i}" for i, root in enumerate(sorted(members))}
    nod = ["<nodes>"]
    for root, pts in sorted(members.items()):
        x, y = np.mean(pts, axis=0)
        nod.append(f'  <node id="{name[root]}" x="{x:.3f}" y="{y:.3f}" type="priority"/>')
    nod.append("</nodes>")
    edg = ["<edges>"]
    for g in groups:
        outer = (g[0].right + g[-1].left) / 2 if len(g[0].right) == len(g[-1].left) else g[0].centre
        edg.append(
            f'  <edge id="{edge_id(g)}" from="{name[nodes.find((g[0].id, 0))]}" '
            f'to="{name[nodes.find((g[0].id, 1))]}" numLanes="{len(g)}" '
            f'speed="{max(ln.speed_limit for ln in g):.4f}" spreadType="center" '
            f"shape={quoteattr(_shape(outer))}>"
        )
        for i, ln in enumerate(g):
            edg.append(
                f'    <lane index="{i}" width="{ln.width:.3f}" speed="{ln.speed_limit:.4f}" '
                f"shape={quoteattr(_shape(ln.centre))}/>"
            )
        edg.append("  </edge>")
    edg.append("</edges>")
    con = ["<connections>"]
    for ln in lanelets:
        for succ in ln.successors:
            if succ in by_id:
                (fe, fl), (te, tl) = lane_of[ln.id], lane_of[succ]
                con.append(f'  <connection from="{fe}" to="{te}" fromLane="{fl}" toLane="{tl}"/>')
    con.append("</connections>")
    return "\n".join(nod) + "\n", "\n".join(edg) + "\n", "\n".join(con) + "\n"


def lanelet_edges(lanelets: Sequence[Lanelet]) -> dict[int, tuple[str, int]]:
    """lanelet id -> (edge id, lane index) in the built network."""
    groups = _lanes_right_to_left({ln.id: ln for ln in lanelets})
    return {ln.id: (edge_id(g), i) for g in groups for i, ln in enumerate(g)}


def build_lanelet_net(name: str, lanelets: Sequence[Lanelet], cache_dir: Path) -> Path:
    """The ``.net.xml`` of a lanelet network, built once into ``cache_dir`` (keyed by the hash of
    the netconvert inputs) and reused."""
    options = (*NETCONVERT_OPTIONS, *LANELET_NET_OPTIONS)
    return convert_plain_xml(name, plain_xml(lanelets), options, cache_dir)
