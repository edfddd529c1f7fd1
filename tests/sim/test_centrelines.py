"""The batched waypoint sampling gives np.interp's values over each lane's own polyline, bit for
bit (observations and records must not change with it)."""

import math

import numpy as np
import pytest

from arena.scenario import load_scenario
from arena.suite import SHIPPED_PUBLIC_DIR
from sim.road import RoadNetwork
from sim.road.centrelines import CentrelineTable
from sim.road.lane import Lane


def per_lane(lane: Lane, s: np.ndarray) -> np.ndarray:
    """The waypoint values sampled on the lane alone: np.interp, and the heading of the segment
    under each offset (the last one within 1e-9 m of the lane's end)."""
    cum = lane.cumulative_s
    heading = lane.segment_headings[
        cum[1:-1].searchsorted(np.minimum(s, lane.length - 1e-9), side="right")
    ]
    return np.stack(
        [
            np.interp(s, cum, lane.centreline[:, 0]).round(4),
            np.interp(s, cum, lane.centreline[:, 1]).round(4),
            heading,
            np.full(len(s), lane.width),
            np.full(len(s), lane.speed_limit),
            s,
            np.full(len(s), float(lane.index)),
        ]
    )


def random_pieces(lanes: list[Lane], rng: np.random.Generator) -> list[tuple[Lane, float, int]]:
    """Pieces from the lane's start, from a vertex, from anywhere, and the lane's end point."""
    pieces = []
    for k in rng.choice(len(lanes), size=rng.integers(1, 6)):
        lane = lanes[k]
        first = [
            0.0,
            lane.length,
            float(lane.cumulative_s[rng.integers(len(lane.cumulative_s))]),
            float(rng.uniform(0.0, lane.length)),
        ][rng.integers(4)]
        if first == lane.length:
            pieces.append((lane, first, 1))
        else:
            pieces.append((lane, first, min(int(rng.integers(0, 60)), lane.waypoint_count(first))))
    return pieces


def assert_sampled_as_per_lane(lanes: list[Lane], rounds: int) -> None:
    table, rng = CentrelineTable(lanes), np.random.default_rng(0)
    for _ in range(rounds):
        pieces = random_pieces(lanes, rng)
        got = table.sample(pieces, [sum(n for *_, n in pieces)])
        expected = [per_lane(lane, first + np.arange(n)) for lane, first, n in pieces if n]
        want = np.concatenate(expected, axis=1) if expected else np.zeros((7, 0))
        assert got.values.tobytes() == want.tobytes(), pieces  # also the signs of zeros
        assert got.pieces == [(lane, n) for lane, _, n in pieces if n]


@pytest.mark.parametrize(
    "scenario_id", ["p000_left_turn_t_low", "p020_cruise_3lane_curve_low_3agents"]
)
def test_public_maps_are_sampled_as_lane_by_lane(scenario_id):
    folder = SHIPPED_PUBLIC_DIR / scenario_id
    road = RoadNetwork.load(folder / load_scenario(folder).map)
    assert_sampled_as_per_lane(list(road.lanes.values()), 300)


def test_negative_zeros_repeated_vertices_and_tiny_end_segments_are_sampled_as_np_interp():
    centrelines = [
        [[-0.0, -0.0], [0.0, 5.0], [0.0, 5.0], [-0.0, 9.0], [-0.0, 9.0 + 1e-10]],
        [[3.0, -0.0], [-3.0, -0.0]],
        [[0.1, 0.2], [0.1, 0.2 + 1e-3]],
    ]
    lanes = [
        Lane(f"L_{i}", "L", i, np.array(c), 3.2, 10.0, is_internal=False, is_shoulder=False)
        for i, c in enumerate(centrelines)
    ]
    assert math.copysign(1.0, lanes[0].centreline[0, 0]) == -1.0
    assert_sampled_as_per_lane(lanes, 2000)
