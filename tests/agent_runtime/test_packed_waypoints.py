"""The runtime's builder of waypoint dicts from the protocol's packed paths."""

from __future__ import annotations

import struct

import pytest

from agent_runtime.packed_waypoints import expand_observations, waypoint_paths

LANES = [("E1_0", 0, 3.2, 13.89, 2), ("J1_0", 0, 3.0, 8.0, 1), ("E1_1", 1, 3.2, 13.89, 1)]
VALUES = [1.0, 2.0, 0.1, 5.0, 2.0, 2.0, 0.1, 6.0, 3.0, 2.5, -0.0, 0.25, 1.0, 5.2, 0.1, 5.0]


def packed(values=VALUES, counts=(3, 1), lanes=LANES):
    return list(counts), lanes, struct.pack(f"{len(values)}d", *values)


def test_paths_hold_each_points_values_and_its_lanes_constants_in_the_documented_order() -> None:
    first, second = waypoint_paths(*packed())
    assert [len(first), len(second)] == [3, 1]
    assert first[2] == {
        "pos": [3.0, 2.5],
        "heading": -0.0,
        "lane_id": "J1_0",
        "lane_index": 0,
        "lane_width": 3.0,
        "speed_limit": 8.0,
        "lane_offset": 0.25,
    }
    assert list(first[2]) == [
        "pos",
        "heading",
        "lane_id",
        "lane_index",
        "lane_width",
        "speed_limit",
        "lane_offset",
    ]
    assert second[0]["lane_id"] == "E1_1" and second[0]["pos"] == [1.0, 5.2]
    # Every point has its own dict and position list: a policy may change one.
    first[0]["pos"][0] = 99.0
    assert first[1]["pos"] == [2.0, 2.0]


@pytest.mark.parametrize(
    "broken",
    [
        packed(values=VALUES[:-4]),
        packed(counts=(3, 2)),
        packed(lanes=LANES[:2]),
    ],
    ids=["values short", "counts over", "lanes short"],
)
def test_disagreeing_parts_are_refused(broken) -> None:
    with pytest.raises(ValueError, match="disagree"):
        waypoint_paths(*broken)


def test_expanding_leaves_dicts_and_other_messages_alone() -> None:
    already = [[{"pos": [0.0, 0.0]}]]
    observations = {"a": {"waypoint_paths": packed()}, "b": {"waypoint_paths": already}, "c": {}}
    expand_observations(observations)
    assert len(observations["a"]["waypoint_paths"]) == 2
    assert observations["b"]["waypoint_paths"] is already
    assert observations["c"] == {}
    expand_observations(None)  # a message with no observations
