"""Which recorded vehicles are one: matched by the shape of their motion at one constant frame
offset, across files of one recording (other ids, other clocks) or moved copies, never within
one file; a shapeless cruise only where a neighbour agrees."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from arena.scenario import DataLabel
from scenarios.recorded.corpus import CorpusScene, _identities
from scenarios.recorded.naturalistic import NaturalisticScene
from scenarios.recorded.provenance import Provenance
from scenarios.recorded.tracks import TrackIndex, track_poses
from sim.trajectories import Trajectory


def drive(vid: str, x0: float, frames: range, speed: float = 10.0, t0: int = 0) -> Trajectory:
    """A vehicle near y = 0 at about ``x0 + speed * t`` over the recording's ``frames``, seen
    through a scene clock starting at recording frame ``t0``."""
    t = np.array(frames, float) * 0.1
    x = x0 + speed * t + np.sin(t)  # not constant speed: real traffic
    return Trajectory(
        vid,
        np.round(t - t0 * 0.1, 1),
        x,
        0.01 * np.sin(7 * t),
        np.zeros(len(t)),
        np.full(len(t), speed),
        4.5,
        1.8,
    )


def scene(name: str, *tracks: Trajectory) -> CorpusScene:
    prov = Provenance(DataLabel.naturalistic, "NGSIM", "", None)
    return CorpusScene(NaturalisticScene(name, Path(name), (), tracks, prov), Path(), (), {})


def test_the_same_vehicle_through_two_clocks_is_one_and_a_follower_is_not():
    leader = drive("a", 0.0, range(0, 80))
    same_later = drive("b", 0.0, range(40, 120), t0=40)  # file 2: frames from 40, clock at 0
    index = TrackIndex()
    index.add("A", {"leader": track_poses(leader)})
    assert index.same_vehicles({"b": track_poses(same_later)}) == {"b": {("A", "leader")}}
    # A follower on the same line 20 m behind passes the same points, but not at one offset
    # of frames (its speed varies out of phase with the leader's).
    follower = drive("c", -20.0, range(0, 80))
    follower = Trajectory(
        "c",
        follower.time,
        follower.x + 0.3 * np.sin(follower.time * 2.3),
        follower.y,
        follower.heading,
        follower.speed,
        4.5,
        1.8,
    )
    assert index.same_vehicles({"c": track_poses(follower)}) == {}


def test_identities_link_scenes_transitively_but_never_two_vehicles_of_one_file():
    first = drive("1", 0.0, range(0, 50))
    middle = drive("2", 0.0, range(30, 130), t0=30)
    last = drive("3", 0.0, range(110, 200), t0=110)  # overlaps the middle one only
    twin = drive("9", 0.0, range(0, 50))  # an identical track of the first file: simulated
    identity = _identities([scene("A_1", first, twin), scene("A_2", middle), scene("A_3", last)])
    assert identity[("A_3", "3")] == identity[("A_2", "2")] == identity[("A_1", "1")]
    assert identity[("A_1", "9")] != identity[("A_1", "1")]


def moved(tr: Trajectory, angle: float, shift: tuple[float, float], frames: int) -> Trajectory:
    """``tr`` turned by ``angle`` about 0, 0, shifted, and ``frames`` later."""
    c, s = np.cos(angle), np.sin(angle)
    return Trajectory(
        tr.vehicle_id + "'",
        np.round(tr.time + frames * 0.1, 1),
        c * tr.x - s * tr.y + shift[0],
        s * tr.x + c * tr.y + shift[1],
        tr.heading + angle,
        tr.speed,
        tr.length,
        tr.width,
    )


def test_a_turned_shifted_delayed_copy_is_the_same_vehicle_and_a_lone_cruise_needs_a_neighbour():
    shaped = drive("a", 0.0, range(0, 60), speed=6.0)
    shaped = Trajectory(
        "a", shaped.time, shaped.x, 0.05 * shaped.x**1.5, *(shaped.heading,), shaped.speed, 4.5, 1.8
    )
    index = TrackIndex()
    index.add("A", {"a": track_poses(shaped)})
    copy = moved(shaped, np.pi / 2, (686000.0, 5335000.0), 40)
    assert index.same_vehicles({"b": track_poses(copy)}) == {"b": {("A", "a")}}
    # Straight at one speed: any other such cruise is one rigid motion away. Alone it says
    # nothing; with its neighbour moved by the same motion it is the same scene's vehicle.
    cruise = Trajectory(
        "c",
        np.round(np.arange(60) * 0.1, 1),
        np.arange(60) * 2.5,
        np.zeros(60),
        np.zeros(60),
        np.full(60, 25.0),
        4.5,
        1.8,
    )
    other = Trajectory(
        "o", cruise.time, cruise.x - 300.0, np.full(60, 7.0), cruise.heading, cruise.speed, 4.5, 1.8
    )
    neighbour = Trajectory(
        "n", cruise.time, cruise.x + 12.0, np.full(60, 3.6), cruise.heading, cruise.speed, 4.5, 1.8
    )
    index = TrackIndex()
    index.add("B", {"c": track_poses(cruise), "n": track_poses(neighbour)})
    assert index.same_vehicles({"o": track_poses(other)}) == {}
    copies = {
        v.vehicle_id + "'": track_poses(moved(v, 1.0, (50.0, 9.0), 7)) for v in (cruise, neighbour)
    }
    assert index.same_vehicles(copies) == {"c'": {("B", "c")}, "n'": {("B", "n")}}
