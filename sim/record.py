"""The episode record: per-agent, per-step arrays saved as one compressed ``.npz``.

The arrays and their meaning are documented in ``docs/records.md``; scoring reads nothing else.
The archive is written byte-for-byte deterministically (fixed member order and timestamps), so the
same scenario, seed and actions give an identical file.
"""

from __future__ import annotations

import io
import zipfile
from pathlib import Path
from typing import NamedTuple

import numpy as np

from arena.outcome import AgentOutcome
from arena.record_format import EVENT_FLAGS, FORMAT_VERSION, NEIGHBOUR_FLOATS, STEP_FLOATS
from arena.scenario import Mission
from sim.vehicle.states import VehicleStates


class RecordRow(NamedTuple):
    """One agent-step: the state after the step was applied. (A NamedTuple: immutable, and
    several times cheaper to make than a frozen dataclass, once per agent-step.)"""

    step: int
    x: float
    y: float
    heading: float
    speed: float
    vx: float
    vy: float
    lane_id: str
    lane_index: int
    lane_offset: float
    lane_width: float
    lane_heading: float
    speed_limit: float
    in_junction: bool
    flags: tuple[bool, ...]  # in EVENT_FLAGS order
    neighbours: VehicleStates  # within the observation radius, nearest first


class EpisodeRecorder:
    """Collects rows during an episode and writes the archive at the end."""

    def __init__(self, agent_ids: list[str]) -> None:
        self.agent_ids = agent_ids
        self.rows: dict[str, list[RecordRow]] = {a: [] for a in agent_ids}

    def add(self, agent_id: str, row: RecordRow) -> None:
        self.rows[agent_id].append(row)

    def arrays(
        self,
        meta: dict[str, object],
        outcomes: tuple[AgentOutcome, ...],
        missions: tuple[Mission, ...],
    ) -> dict[str, np.ndarray]:
        """Every record array by name (see docs/records.md); ``outcomes`` and ``missions`` in
        the order of the recorder's agent ids."""
        n_agents = len(self.agent_ids)
        n_rows = max((len(r) for r in self.rows.values()), default=0)
        n_slots = max([1] + [len(row.neighbours) for rows in self.rows.values() for row in rows])
        out: dict[str, np.ndarray] = {
            "format_version": np.array(FORMAT_VERSION),
            "scenario_id": _str_array(meta["scenario_id"]),
            "scenario_hash": _str_array(meta["scenario_hash"]),
            "seed": np.array(int(meta["seed"])),
            "dt": np.array(float(meta["dt"])),
            "max_episode_steps": np.array(int(meta["max_episode_steps"])),
            "episode_steps": np.array(int(meta["episode_steps"])),
            "agent_ids": _str_array([o.id for o in outcomes]),
            "start_step": np.array([m.start_step for m in missions], dtype=np.int64),
            "steps": np.array([o.steps for o in outcomes], dtype=np.int64),
            "done_step": np.array([o.done_step for o in outcomes], dtype=np.int64),
            "done_reason": _str_array([str(o.reason) for o in outcomes]),
            "reached_goal": np.array([o.reached_goal for o in outcomes], dtype=bool),
            "length": np.array([m.vehicle.length for m in missions], dtype=np.float64),
            "width": np.array([m.vehicle.width for m in missions], dtype=np.float64),
            "goal_x": np.array([m.goal.position[0] for m in missions], dtype=np.float64),
            "goal_y": np.array([m.goal.position[1] for m in missions], dtype=np.float64),
            "goal_radius": np.array([m.goal.radius for m in missions], dtype=np.float64),
        }
        shape = (n_agents, n_rows)
        out["valid"] = np.zeros(shape, dtype=bool)
        out["step"] = np.zeros(shape, dtype=np.int64)
        out["lane_index"] = np.full(shape, -1, dtype=np.int64)
        out["in_junction"] = np.zeros(shape, dtype=bool)
        for name in STEP_FLOATS:
            out[name] = np.full(shape, np.nan)
        for name in EVENT_FLAGS:
            out[name] = np.zeros(shape, dtype=bool)
        lane_ids = [[""] * n_rows for _ in range(n_agents)]
        nbr_shape = (n_agents, n_rows, n_slots)
        out["nbr_valid"] = np.zeros(nbr_shape, dtype=bool)
        for name in NEIGHBOUR_FLOATS:
            out[f"nbr_{name}"] = np.full(nbr_shape, np.nan)
        nbr_ids = []  # (agent, rows, slots, ids) of each agent with neighbours
        for a, agent_id in enumerate(self.agent_ids):
            rows = self.rows[agent_id]
            if not rows:
                continue
            n = len(rows)
            out["valid"][a, :n] = True
            out["step"][a, :n] = [r.step for r in rows]
            out["lane_index"][a, :n] = [r.lane_index for r in rows]
            out["in_junction"][a, :n] = [r.in_junction for r in rows]
            for name in STEP_FLOATS:
                out[name][a, :n] = [getattr(r, name) for r in rows]
            flags = np.array([r.flags for r in rows], dtype=bool)
            for j, name in enumerate(EVENT_FLAGS):
                out[name][a, :n] = flags[:, j]
            lane_ids[a][:n] = [r.lane_id for r in rows]
            # Every neighbour of every row at once: row t's k neighbours go to slots 0..k-1.
            counts = np.array([len(r.neighbours) for r in rows], dtype=np.int64)
            if counts.sum() == 0:
                continue
            row_of = np.repeat(np.arange(n), counts)
            slot_of = np.arange(len(row_of)) - np.repeat(np.cumsum(counts) - counts, counts)
            out["nbr_valid"][a, row_of, slot_of] = True
            for name in NEIGHBOUR_FLOATS:
                out[f"nbr_{name}"][a, row_of, slot_of] = np.concatenate(
                    [getattr(r.neighbours, name) for r in rows]
                )
            nbr_ids.append((a, row_of, slot_of, [i for r in rows for i in r.neighbours.ids]))
        out["lane_id"] = _str_array(lane_ids)
        # As _str_array would make it from nested lists: fixed width of the longest id.
        width = max([1] + [len(i) for *_, ids in nbr_ids for i in ids])
        out["nbr_id"] = np.full(nbr_shape, "", dtype=f"<U{width}")
        for a, row_of, slot_of, ids in nbr_ids:
            out["nbr_id"][a, row_of, slot_of] = ids
        return out


def _str_array(value) -> np.ndarray:
    """Fixed-width unicode array (never object dtype, so loading needs no pickle)."""
    arr = np.array(value, dtype=str)
    return arr if arr.dtype.itemsize else arr.astype("<U1")


def write_npz(path: Path, arrays: dict[str, np.ndarray]) -> None:
    """``np.savez_compressed``-compatible archive with fixed member order and timestamps."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".partial")
    with zipfile.ZipFile(tmp, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        for name in sorted(arrays):
            buffer = io.BytesIO()
            np.lib.format.write_array(buffer, np.asarray(arrays[name]), allow_pickle=False)
            info = zipfile.ZipInfo(f"{name}.npy", date_time=(1980, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = 0o600 << 16
            zf.writestr(info, buffer.getvalue())
    tmp.replace(path)
