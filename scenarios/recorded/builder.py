"""Builds replay scenarios from a recording: removes one or two recorded vehicles and puts mission
vehicles in their place (their start state; goal where they ended; route the edges they drove).

Removed vehicles are chosen so their recorded path is a meaningful example of the scenario kind
and collides with no other recorded vehicle; the removed path is kept as ``expert.csv`` (the log
replay expert of ``arena scenarios verify``).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from arena.scenario import DataLabel, Family, Goal, Mission, Scenario, VehicleDims
from scenarios.netinfo import NetInfo
from scenarios.recorded.recorder import Recording
from scenarios.writer import TRAJECTORIES_FILE, replay_traffic, write_scenario
from sim.geometry import box_corners, boxes_overlap
from sim.trajectories import Trajectory, write_trajectories

EXPERT_FILE = "expert.csv"
MAX_PATH_S = 70.0  # [s] a removed vehicle's path must fit well inside 800 steps
TAIL_S = 3.0  # [s]
# Scenes stop inserting traffic this long before their end (scenes.py): removed vehicles must be
# done before, so that recorded traffic still surrounds them.
FLOWS_STOP_BEFORE_END_S = 60.0
NEARBY_M = 150.0  # [m] recorded vehicles farther than this from every mission vehicle are dropped

# kind -> scene it is cut from


@dataclass(frozen=True)
class Candidate:
    vehicle_ids: tuple[str, ...]


def _lane_changes(rec: Recording, vid: str) -> list[int]:
    """Signed lane changes (+1 left, -1 right) in the order driven."""
    seq: list[int] = []
    for lane in rec.lanes[vid]:
        main_lane = _main_lane(lane)
        if main_lane > -90 and (not seq or seq[-1] != main_lane):
            seq.append(main_lane)
    return [int(np.sign(b - a)) for a, b in itertools.pairwise(seq)]


def _complete(rec: Recording, vid: str, duration_s: float) -> bool:
    tr = rec.trajectories[vid]
    return (
        tr.time[0] > 1.0
        and tr.time[-1] < duration_s - FLOWS_STOP_BEFORE_END_S - 5.0
        and tr.time[-1] - tr.time[0] <= MAX_PATH_S
        and len(rec.edges[vid]) >= 2
    )


def _classify(rec: Recording, vid: str, info: NetInfo, scene: str) -> str | None:
    edges = rec.edges[vid]
    if scene == "highway":
        changes = _lane_changes(rec, vid)
        if edges[0] == "ramp":
            return "merge"
        if not changes:
            return "cruise"
        if 1 in changes and -1 in changes[changes.index(1) + 1 :]:
            return "overtake"
        if len(changes) == 1:
            return "lane_change"
        return None
    if scene == "cross":
        for kind, direction in (("right_turn", "r"), ("left_turn", "l")):
            if info.turn(edges[0], direction) == edges[1]:
                return kind
        return None
    return "urban" if len(edges) >= 3 else None


class _Frames:
    """Every recorded vehicle on one global frame grid: (V, T) arrays, NaN where absent."""

    def __init__(self, rec: Recording) -> None:
        self.ids = sorted(rec.trajectories)
        self.row = {vid: i for i, vid in enumerate(self.ids)}
        n_frames = 1 + max(round(tr.time[-1] / 0.1) for tr in rec.trajectories.values())
        self.x = np.full((len(self.ids), n_frames), np.nan)
        self.y = np.full_like(self.x, np.nan)
        self.h = np.full_like(self.x, np.nan)
        self.lane = np.full(self.x.shape, -99, dtype=int)  # main-carriageway lane index
        self.dims = np.zeros((len(self.ids), 2))
        for i, vid in enumerate(self.ids):
            tr = rec.trajectories[vid]
            f = np.round(tr.time / 0.1).astype(int)
            self.x[i, f], self.y[i, f], self.h[i, f] = tr.x, tr.y, tr.heading
            self.lane[i, f] = [_main_lane(lane) for lane in rec.lanes[vid]]
            self.dims[i] = (tr.length, tr.width)

    def frames(self, vid: str) -> np.ndarray:
        return np.flatnonzero(~np.isnan(self.x[self.row[vid]]))

    def collision_free(self, vids: tuple[str, ...]) -> bool:
        for vid in vids:
            i, f = self.row[vid], self.frames(vid)
            dist = np.hypot(self.x[:, f] - self.x[i, f], self.y[:, f] - self.y[i, f])
            dist[i] = np.inf
            js, ks = np.nonzero(dist < 7.0)  # closer than any two car diagonals: test the boxes
            if len(js) == 0:
                continue
            fk = f[ks]
            length_i, width_i = self.dims[i]
            a = box_corners(self.x[i, fk], self.y[i, fk], self.h[i, fk], length_i, width_i)
            b = box_corners(
                self.x[js, fk], self.y[js, fk], self.h[js, fk], self.dims[js, 0], self.dims[js, 1]
            )
            if boxes_overlap(a, b).any():
                return False
        return True

    def cut_off_gap(self, vid: str) -> float:
        """Smallest gap [m] to a vehicle behind in the lane just entered, 1 s after a change."""
        i, f = self.row[vid], self.frames(vid)
        lanes = self.lane[i, f]
        best = np.inf
        for k in np.flatnonzero((lanes[1:] != lanes[:-1]) & (lanes[1:] > -90) & (lanes[:-1] > -90)):
            j = f[min(k + 11, len(f) - 1)]
            behind = (self.lane[:, j] == self.lane[i, j]) & (self.x[:, j] < self.x[i, j])
            if behind.any():
                gap = self.x[i, j] - self.x[behind, j].max() - self.dims[i, 0]
                best = min(best, float(gap))
        return best


def _main_lane(lane: str) -> int:
    """Lane index on the main carriageway (the acceleration lane is -1), -99 inside junctions."""
    if lane.startswith(":"):
        return -99
    edge, index = lane.rsplit("_", 1)
    return int(index) - (1 if edge == "merge" else 0)


def candidates(
    rec: Recording, info: NetInfo, scene: str, duration_s: float
) -> dict[str, list[Candidate]]:
    """Collision-free removable vehicles (or pairs) per kind, in vehicle-id order."""
    grid = _Frames(rec)
    by_kind: dict[str, list[Candidate]] = {}
    for vid in sorted(rec.trajectories):
        if not _complete(rec, vid, duration_s):
            continue
        kind = _classify(rec, vid, info, scene)
        if kind is not None and grid.collision_free((vid,)):
            by_kind.setdefault(kind, []).append(Candidate((vid,)))
    if scene == "highway":
        lane_changers = by_kind.get("lane_change", [])
        gaps = sorted(
            ((grid.cut_off_gap(c.vehicle_ids[0]), c) for c in lane_changers), key=lambda g: g[0]
        )
        by_kind["cut_off"] = [c for gap, c in gaps if gap < 20.0][:3]
        by_kind["i80_bubble"] = list(by_kind.get("cruise", []))
        by_kind["merge_pair"] = _merge_pairs(rec, by_kind.get("merge", []))
    return by_kind


def _merge_pairs(rec: Recording, merges: list[Candidate]) -> list[Candidate]:
    """Two ramp vehicles entering 2-8 s apart: two agents merging one after the other."""
    starts = sorted((rec.trajectories[c.vehicle_ids[0]].time[0], c.vehicle_ids[0]) for c in merges)
    pairs = []
    for (t_a, a), (t_b, b) in itertools.pairwise(starts):
        if 2.0 <= t_b - t_a <= 8.0:
            pairs.append(Candidate((a, b)))
    return pairs


def _crop(tr: Trajectory, t0: float, t1: float) -> Trajectory | None:
    keep = (tr.time >= t0 - 1e-6) & (tr.time <= t1 + 1e-6)
    if not keep.any():
        return None
    return Trajectory(
        tr.vehicle_id,
        np.round(tr.time[keep] - t0, 1),
        tr.x[keep],
        tr.y[keep],
        tr.heading[keep],
        tr.speed[keep],
        tr.length,
        tr.width,
    )


def _near_any(other: Trajectory, egos: list[Trajectory]) -> bool:
    for ego in egos:
        common = np.intersect1d(np.round(ego.time, 1), np.round(other.time, 1))
        if len(common) == 0:
            continue
        ia = np.round((common - ego.time[0]) / 0.1).astype(int)
        ib = np.round((common - other.time[0]) / 0.1).astype(int)
        if np.hypot(ego.x[ia] - other.x[ib], ego.y[ia] - other.y[ib]).min() <= NEARBY_M:
            return True
    return False


def write_replay(
    folder: Path,
    scenario_id: str,
    variant: str,
    rec: Recording,
    candidate: Candidate,
    net_path: Path,
    seed: int,
    bubble_radius: float | None = None,
) -> Scenario:
    egos_full = [rec.trajectories[v] for v in candidate.vehicle_ids]
    t0 = min(float(e.time[0]) for e in egos_full)
    t1 = max(float(e.time[-1]) for e in egos_full)
    egos = [_crop(e, t0, t1) for e in egos_full]
    others = []
    for vid, tr in rec.trajectories.items():
        if vid in candidate.vehicle_ids:
            continue
        # Recorded traffic outlasts the mission vehicles' paths a little, so the scene does not
        # empty the moment the expert arrives.
        cropped = _crop(tr, t0, t1 + TAIL_S)
        if cropped is None:
            continue
        if _near_any(cropped, egos) or cropped.time[-1] >= t1 - t0 + TAIL_S - 0.05:
            others.append(cropped)
    missions = []
    for i, (vid, ego) in enumerate(zip(candidate.vehicle_ids, egos, strict=True)):
        missions.append(
            Mission(
                agent_id=f"Agent_{i}",
                start=(round(ego.x[0], 3), round(ego.y[0], 3), round(ego.heading[0], 5)),
                start_speed=round(float(ego.speed[0]), 3),
                start_step=round(float(ego.time[0]) / 0.1),
                route=rec.edges[vid],
                goal=Goal(position=(round(ego.x[-1], 3), round(ego.y[-1], 3))),
                vehicle=VehicleDims(length=ego.length, width=ego.width),
            )
        )
    folder.mkdir(parents=True, exist_ok=True)
    write_trajectories(folder / TRAJECTORIES_FILE, others)
    write_trajectories(
        folder / EXPERT_FILE,
        [
            Trajectory(
                f"Agent_{i}",
                *(getattr(e, f) for f in ("time", "x", "y", "heading", "speed")),
                e.length,
                e.width,
            )
            for i, e in enumerate(egos)
        ],
    )
    scenario = Scenario(
        id=scenario_id,
        family=Family.replay,
        variant=variant,
        volume=None,
        agents=len(missions),
        reactive=bubble_radius is not None,
        seed=seed,
        map="map.net.xml",
        missions=tuple(missions),
        traffic=replay_traffic(bubble_radius),
        label=DataLabel.recorded,
    )
    return write_scenario(folder, scenario, net_path)
