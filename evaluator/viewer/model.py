"""One episode ready to be watched: the map once, then every vehicle's pose per frame, the mission
agents' speed and events. Built from a stored record (``docs/records.md``); the replay page, the
self-contained HTML file and the GIF/MP4 frames all draw from it.

Frame ``f`` is episode step ``first_step + f``. Background vehicles are known only where some
mission agent observed them (within its 100 m observation radius): a vehicle is absent (NaN) in a
frame where no agent saw it.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path

import numpy as np

from arena.errors import ArenaError, RecordError
from arena.record_format import EVENT_FLAGS
from evaluator.scoring.record import read_arrays, scalar
from sim import render
from sim.render import RoadGeometry

REPLAY_FORMAT = 1
MAP_MARGIN_M = 40.0  # the whole-map view: around the mission agents' paths and goals
MISSION_COLOUR = "#f2a541"
EVENT_COLOURS = {
    "collision": "#d62728",
    "off_road": "#ff7f0e",
    "off_route": "#9467bd",
    "on_shoulder": "#8c564b",
    "wrong_way": "#e377c2",
    "not_moving": "#7f7f7f",
    "reached_goal": render.GOAL_COLOUR,
}
# Every picture of a replay (page, HTML file, video frames) takes its colours from here.
STYLE = {
    "background": render.BACKGROUND,
    "road": render.ROAD_COLOUR,
    "junction": render.JUNCTION_COLOUR,
    "shoulder": render.SHOULDER_COLOUR,
    "marking": render.MARKING_COLOUR,
    "stop_line": render.STOP_LINE_COLOUR,
    "goal": render.GOAL_COLOUR,
    "ego": render.EGO_COLOUR,
    "mission": MISSION_COLOUR,
    "traffic": render.TRAFFIC_COLOUR,
    "events": EVENT_COLOURS,
}


class ReplayError(ArenaError, ValueError):
    """A replay cannot be made: no record, or no way to write the asked format."""


class VehicleKind(StrEnum):
    ego = "ego"  # the first mission agent, followed by the camera by default
    mission = "mission"  # the other mission agents
    traffic = "traffic"


@dataclass(frozen=True)
class AgentTimeline:
    """One mission agent over the frames; per-frame arrays ``(F,)``, NaN where it did not
    drive."""

    id: str
    vehicle: int  # index into Replay.vehicle_ids
    speed: np.ndarray  # [m/s]
    speed_limit: np.ndarray  # [m/s]
    events: tuple[tuple[int, str], ...]  # (frame, event name) where an event starts
    goal: tuple[float, float, float]  # centre x, y and radius [m]
    done_reason: str
    done_step: int


@dataclass(frozen=True)
class Replay:
    scenario_id: str
    dt: float  # [s]
    first_step: int  # episode step of frame 0
    vehicle_ids: tuple[str, ...]  # (V,)
    kinds: tuple[VehicleKind, ...]  # (V,)
    length: np.ndarray  # (V,) [m]
    width: np.ndarray  # (V,) [m]
    x: np.ndarray  # (V, F) [m], NaN where the vehicle is not known
    y: np.ndarray  # (V, F) [m]
    heading: np.ndarray  # (V, F) [rad]
    agents: tuple[AgentTimeline, ...]
    road: RoadGeometry | None  # None when the scenario folder was not at hand
    bounds: tuple[float, float, float, float]  # xmin, ymin, xmax, ymax [m] of what is drawn

    @property
    def frames(self) -> int:
        return self.x.shape[1]

    def to_json(self) -> dict:
        """The replay as the page's script reads it (coordinates rounded to centimetres)."""
        return {
            "format": REPLAY_FORMAT,
            "scenario_id": self.scenario_id,
            "dt": self.dt,
            "first_step": self.first_step,
            "frames": self.frames,
            "bounds": [round(v, 2) for v in self.bounds],
            "style": STYLE,
            "map": _road_json(self.road) if self.road is not None else None,
            "vehicles": [self._vehicle_json(v) for v in range(len(self.vehicle_ids))],
            "agents": [
                {
                    "id": a.id,
                    "vehicle": a.vehicle,
                    "speed": _values(a.speed, 2),
                    "speed_limit": _values(a.speed_limit, 2),
                    "events": [[frame, name] for frame, name in a.events],
                    "goal": [round(v, 2) for v in a.goal],
                    "done_reason": a.done_reason,
                    "done_step": a.done_step,
                }
                for a in self.agents
            ],
        }

    def _vehicle_json(self, v: int) -> dict:
        """Poses from the first to the last frame the vehicle is known (``start``), null in the
        gaps: most traffic is in view for only part of the episode."""
        known = np.flatnonzero(np.isfinite(self.x[v]))
        start, stop = (int(known[0]), int(known[-1]) + 1) if len(known) else (0, 0)
        return {
            "id": self.vehicle_ids[v],
            "kind": self.kinds[v].value,
            "length": round(float(self.length[v]), 2),
            "width": round(float(self.width[v]), 2),
            "start": start,
            "x": _values(self.x[v, start:stop], 2),
            "y": _values(self.y[v, start:stop], 2),
            "heading": _values(self.heading[v, start:stop], 3),
        }


def _values(array: np.ndarray, digits: int) -> list[float | None]:
    return [round(float(v), digits) if np.isfinite(v) else None for v in array]


def _points(polygon: np.ndarray) -> list[list[float]]:
    return np.round(polygon, 2).tolist()


def _road_json(road: RoadGeometry) -> dict:
    return {
        name: [_points(shape) for shape in getattr(road, name)]
        for name in ("junctions", "lanes", "shoulders", "dashed", "solid", "stop_lines")
    }


def load_replay(record: Path, suite_dir: Path | None = None) -> Replay:
    """The replay of the record at ``record``, over its scenario's map when the scenario's folder
    is in ``suite_dir``."""
    arrays = read_arrays(record)
    try:
        folder = scenario_folder(suite_dir, str(scalar(arrays["scenario_id"])))
        return replay_from_arrays(arrays, _road(folder) if folder else None)
    except KeyError as exc:
        raise RecordError(f"{record}: missing array {exc}") from None
    except RecordError as exc:
        raise RecordError(f"{record}: {exc}") from None


def scenario_folder(suite_dir: Path | None, scenario_id: str) -> Path | None:
    """The scenario's folder in the suite, where its map is; None when it is not there."""
    if suite_dir is None:
        return None
    folder = Path(suite_dir) / scenario_id
    return folder if (folder / "scenario.json").exists() else None


def _road(scenario_dir: Path) -> RoadGeometry:
    # deferred: CLI start-up (the CLI imports this module); the road needs the simulator
    from arena.scenario import load_scenario
    from scenarios.picture import stop_lanes
    from sim.render import road_geometry
    from sim.road import RoadNetwork

    net_path = Path(scenario_dir) / load_scenario(scenario_dir).map
    return road_geometry(RoadNetwork.load(net_path), stop_lanes(net_path))


def replay_from_arrays(arrays: dict[str, np.ndarray], road: RoadGeometry | None) -> Replay:
    agent_ids = [str(a) for a in arrays["agent_ids"]]
    valid = arrays["valid"].astype(bool)  # (A, T)
    steps = arrays["step"].astype(int)  # (A, T)
    if not valid.any():
        raise RecordError("no agent drove a step: there is nothing to replay")
    first, last = int(steps[valid].min()), int(steps[valid].max())
    n_frames = last - first + 1
    frame = np.where(valid, steps - first, -1)  # (A, T)

    # Background vehicles: the union of what every mission agent saw, step by step.
    a_idx, t_idx, k_idx = np.nonzero(arrays["nbr_valid"] & valid[:, :, None])
    seen_ids = arrays["nbr_id"][a_idx, t_idx, k_idx].astype(str)
    traffic = sorted(set(seen_ids.tolist()) - set(agent_ids))
    ids = agent_ids + traffic
    kinds = [VehicleKind.ego] + [VehicleKind.mission] * (len(agent_ids) - 1)
    kinds += [VehicleKind.traffic] * len(traffic)
    length = np.concatenate([arrays["length"].astype(float), np.zeros(len(traffic))])
    width = np.concatenate([arrays["width"].astype(float), np.zeros(len(traffic))])
    pose = np.full((3, len(ids), n_frames), np.nan)  # x, y, heading
    for a in range(len(agent_ids)):
        for k, name in enumerate(("x", "y", "heading")):
            pose[k, a, frame[a, valid[a]]] = arrays[name][a, valid[a]]
    index = {vehicle: len(agent_ids) + i for i, vehicle in enumerate(traffic)}
    keep = np.isin(seen_ids, traffic)
    rows = np.array([index[v] for v in seen_ids[keep]], dtype=int)
    where = (a_idx[keep], t_idx[keep], k_idx[keep])
    cols = frame[a_idx[keep], t_idx[keep]]
    for k, name in enumerate(("x", "y", "heading")):
        pose[k, rows, cols] = arrays[f"nbr_{name}"][where]
    length[rows] = arrays["nbr_length"][where]
    width[rows] = arrays["nbr_width"][where]

    agents = tuple(
        _timeline(arrays, a, agent_ids[a], frame[a], valid[a], n_frames)
        for a in range(len(agent_ids))
    )
    return Replay(
        scenario_id=str(scalar(arrays["scenario_id"])),
        dt=float(scalar(arrays["dt"])),
        first_step=first,
        vehicle_ids=tuple(ids),
        kinds=tuple(kinds),
        length=length,
        width=width,
        x=pose[0],
        y=pose[1],
        heading=pose[2],
        agents=agents,
        road=road,
        bounds=_bounds(pose[0], pose[1], agents),
    )


def _timeline(
    arrays: dict[str, np.ndarray],
    a: int,
    agent_id: str,
    frame: np.ndarray,
    valid: np.ndarray,
    n_frames: int,
) -> AgentTimeline:
    per_frame = {}
    for name in ("speed", "speed_limit"):
        values = np.full(n_frames, np.nan)
        values[frame[valid]] = arrays[name][a, valid]
        per_frame[name] = values
    events = []
    for flag in EVENT_FLAGS:
        on = arrays[flag][a].astype(bool) & valid
        starts = np.flatnonzero(on & ~np.concatenate([[False], on[:-1]]))
        events += [(int(frame[t]), flag.removeprefix("ev_")) for t in starts]
    return AgentTimeline(
        id=agent_id,
        vehicle=a,
        speed=per_frame["speed"],
        speed_limit=per_frame["speed_limit"],
        events=tuple(sorted(events)),
        goal=(
            float(arrays["goal_x"][a]),
            float(arrays["goal_y"][a]),
            float(arrays["goal_radius"][a]),
        ),
        done_reason=str(arrays["done_reason"][a]),
        done_step=int(arrays["done_step"][a]),
    )


def _bounds(
    x: np.ndarray, y: np.ndarray, agents: tuple[AgentTimeline, ...]
) -> tuple[float, float, float, float]:
    """Around the mission agents' paths and goals (traffic far from them is cut off)."""
    mission = [a.vehicle for a in agents]
    xs = np.concatenate([x[mission][np.isfinite(x[mission])], [a.goal[0] for a in agents]])
    ys = np.concatenate([y[mission][np.isfinite(y[mission])], [a.goal[1] for a in agents]])
    m = MAP_MARGIN_M
    return (
        float(xs.min()) - m,
        float(ys.min()) - m,
        float(xs.max()) + m,
        float(ys.max()) + m,
    )
