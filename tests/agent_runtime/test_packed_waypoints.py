"""The runtime's builder of waypoint dicts from the protocol's packed paths."""

from __future__ import annotations

import copy
import functools
import json
import pickle
import struct
from itertools import chain

import pytest

from agent_runtime.packed_waypoints import (
    expand_observations,
    lazy_waypoint_paths,
    waypoint_paths,
)
from agent_runtime.smarts_compat import SmartsAdapter
from arena.scenario import load_scenario
from arena.suite import SHIPPED_PUBLIC_DIR
from scenarios.experts import PlannerAgent, planner_interface
from sim.simulation import Simulation

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


@pytest.fixture(scope="module")
def episode_observations() -> list[dict]:
    """Every observation of a simulated episode, its waypoint paths packed: the planner driving
    two agents on a curved merge (paths across lane joins, ending, of several widths)."""
    folder = SHIPPED_PUBLIC_DIR / "p012_merge_3lane_curve_mid_2agents"
    sim = Simulation(load_scenario(folder), folder, planner_interface(), packed_waypoints=True)
    planner, found = PlannerAgent(), []
    try:
        obs = sim.reset()
        while obs and not sim.done and len(found) < 120:
            found += copy.deepcopy(list(obs.values()))
            for o in obs.values():
                o["waypoint_paths"] = waypoint_paths(*o["waypoint_paths"])
            obs = sim.step(planner.act(obs))
    finally:
        sim.close()
    return found


@pytest.fixture(scope="module")
def episode_paths(episode_observations) -> list:
    return [o["waypoint_paths"] for o in episode_observations]


def test_lazy_paths_are_the_eager_dicts_however_they_are_read(episode_paths) -> None:
    for packed_paths in episode_paths:
        eager = waypoint_paths(*packed_paths)
        lazy = functools.partial(lazy_waypoint_paths, *packed_paths)  # a new, unread one a call

        assert [len(path) for path in lazy()] == [len(path) for path in eager]
        assert lazy() == eager and eager == lazy() and (lazy() != eager) is False
        assert lazy()[0] == eager[0] and eager[-1] == lazy()[-1]
        assert lazy() == lazy()  # two unfilled paths compare by their dicts
        assert json.dumps(lazy()) == json.dumps(eager)
        assert repr(lazy()) == repr(eager)
        assert [list(w) for path in lazy() for w in path] == [list(w) for p in eager for w in p]
        assert copy.copy(lazy()) == eager
        for copied in (
            pickle.loads(pickle.dumps(lazy())),
            copy.deepcopy(lazy()),
            [path.copy() for path in lazy()],
            [path[:] for path in lazy()],
        ):
            assert copied == eager and all(type(path) is list for path in copied)
        paths = lazy()
        for path, expected in zip(paths, eager, strict=True):
            for i in (0, -1, len(expected) // 2):
                assert path[i] == expected[i] and list(path[i]) == list(expected[i])
            first = path[0]
            assert next(iter(path)) is first  # the dict read before is the one the list holds
            tail = ["x"]  # list + path and path + list read the path as the list it is
            assert path + tail == [*expected, "x"] and tail + path == ["x", *expected]
            path.append("end")
            assert path == [*expected, "end"] and len(path) == len(expected) + 1


def test_a_policy_reading_one_point_of_a_path_makes_only_that_dict(episode_paths) -> None:
    paths = lazy_waypoint_paths(*episode_paths[0])
    assert all(path[0]["lane_id"] for path in paths if path)
    assert all(list.__len__(path) == 0 for path in paths)  # no path made as a whole
    with pytest.raises(IndexError):
        paths[0][len(paths[0])]


def test_the_smarts_adapter_makes_the_same_waypoints_from_packed_paths(episode_observations):
    # The smarts2022 adapter reads a path still packed without its dicts: SMARTS's waypoints
    # are those it makes of the eager dicts, value for value and type for type.
    adapter = SmartsAdapter()
    for o in episode_observations:
        lazy, eager = copy.deepcopy(o), copy.deepcopy(o)
        expand_observations({"a": lazy})
        eager["waypoint_paths"] = waypoint_paths(*eager["waypoint_paths"])
        assert all(path.unread() is not None for path in lazy["waypoint_paths"])
        ours = adapter.observation("Agent_0", lazy).waypoint_paths
        expected = adapter.observation("Agent_0", eager).waypoint_paths
        assert [len(path) for path in ours] == [len(path) for path in expected]
        pairs = zip(chain.from_iterable(ours), chain.from_iterable(expected), strict=True)
        for mine, theirs in pairs:
            assert mine.pos.dtype == theirs.pos.dtype and mine.pos.flags.writeable
            assert mine.pos.tolist() == theirs.pos.tolist()
            for field in ("heading", "lane_id", "lane_width", "speed_limit", "lane_index"):
                assert getattr(mine, field) == getattr(theirs, field)
                assert type(getattr(mine, field)) is type(getattr(theirs, field))
            assert repr(mine.lane_offset) == repr(theirs.lane_offset)
        paths = lazy["waypoint_paths"]
        if paths and paths[0]:
            paths[0][0]  # a dict made: the adapter reads the dicts (the policy may hold it)
            assert paths[0].unread() is None
