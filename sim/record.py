"""The episode record: per-agent, per-step arrays saved as one compressed ``.npz``.

The arrays and their meaning are documented in ``docs/records.md``; scoring reads nothing else.
The archive is written byte-for-byte deterministically (fixed member order and timestamps), so the
same scenario, seed and actions give an identical file.
"""

from __future__ import annotations

import io
import zipfile
from collections.abc import Sequence
from itertools import chain
from pathlib import Path
from typing import NamedTuple, overload

import numpy as np

from arena.files import replaced_atomically
from arena.outcome import AgentOutcome
from arena.record_format import EVENT_FLAGS, FORMAT_VERSION, NEIGHBOUR_FLOATS, STEP_FLOATS
from arena.scenario import Mission
from sim.vehicle.states import FIELDS, VehicleStates


class RecordRow(NamedTuple):
    """One agent-step: the state after the step was applied, as :class:`AgentTrack` hands it
    back (learn's running terms read them)."""

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


_FLOATS = len(STEP_FLOATS)
_FLAGS = len(EVENT_FLAGS)


class AgentTrack(Sequence[RecordRow]):
    """One agent's rows so far, kept as flat columns (Python lists, extended per row) that the
    archive converts once. Reads as a sequence of :class:`RecordRow`, made on access.

    Lists, not preallocated numpy arrays: a row's ~30 values and its neighbours cost ~0.2 µs to
    append and ~1.2 µs to convert at the end, where writing them into arrays grown by doubling
    costs ~3 µs per row (numpy's per-assignment overhead), and learn, which reads every row but
    writes no archive, pays only the appends.
    """

    def __init__(self) -> None:
        self.floats: list[float] = []  # STEP_FLOATS of each row, row after row
        self.ints: list[int] = []  # step, lane_index of each row
        self.bools: list[bool] = []  # in_junction, then the flags in EVENT_FLAGS order
        self.lane_ids: list[str] = []
        self.neighbours: list[VehicleStates] = []  # each row's (immutable: kept, not copied)

    def add(
        self,
        step: int,
        floats: tuple[float, ...],
        lane_id: str,
        lane_index: int,
        in_junction: bool,
        flags: tuple[bool, ...],
        neighbours: VehicleStates,
    ) -> None:
        """Append a row: ``floats`` in STEP_FLOATS order, ``flags`` in EVENT_FLAGS order."""
        self.floats += floats
        self.ints += (step, lane_index)
        self.bools.append(in_junction)
        self.bools += flags
        self.lane_ids.append(lane_id)
        self.neighbours.append(neighbours)

    def __len__(self) -> int:
        return len(self.lane_ids)

    @overload
    def __getitem__(self, index: int) -> RecordRow: ...

    @overload
    def __getitem__(self, index: slice) -> list[RecordRow]: ...

    def __getitem__(self, index):
        if isinstance(index, slice):
            return [self._row(t) for t in range(*index.indices(len(self)))]
        return self._row(range(len(self))[index])  # negative indices; IndexError past the end

    def _row(self, t: int) -> RecordRow:
        f = self.floats[t * _FLOATS : (t + 1) * _FLOATS]
        b = self.bools[t * (1 + _FLAGS) : (t + 1) * (1 + _FLAGS)]
        step, lane_index = self.ints[2 * t : 2 * t + 2]
        return RecordRow(
            step,
            *f[:6],
            self.lane_ids[t],
            lane_index,
            *f[6:],
            b[0],
            tuple(b[1:]),
            self.neighbours[t],
        )

    def columns(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(rows, STEP_FLOATS) floats, (rows, 2) ints (step, lane_index) and (rows, 1 + flags)
        bools (in_junction, flags)."""
        n = len(self)
        return (
            np.array(self.floats, dtype=np.float64).reshape(n, _FLOATS),
            np.array(self.ints, dtype=np.int64).reshape(n, 2),
            np.array(self.bools, dtype=bool).reshape(n, 1 + _FLAGS),
        )


# RecordRow's floats in the track's column order (STEP_FLOATS): x .. vy, then the lane's.
assert RecordRow._fields[1:7] + RecordRow._fields[9:13] == STEP_FLOATS
# A neighbour's row of VehicleStates.values is its record values.
assert FIELDS == NEIGHBOUR_FLOATS


class EpisodeRecorder:
    """Collects each agent's rows during an episode and writes the archive at the end."""

    def __init__(self, agent_ids: list[str]) -> None:
        self.agent_ids = agent_ids
        self.rows: dict[str, AgentTrack] = {a: AgentTrack() for a in agent_ids}

    def add(
        self,
        agent_id: str,
        step: int,
        floats: tuple[float, ...],
        lane_id: str,
        lane_index: int,
        in_junction: bool,
        flags: tuple[bool, ...],
        neighbours: VehicleStates,
    ) -> None:
        """One row of ``agent_id`` (see :meth:`AgentTrack.add`)."""
        self.rows[agent_id].add(step, floats, lane_id, lane_index, in_junction, flags, neighbours)

    def arrays(
        self,
        meta: dict[str, object],
        outcomes: tuple[AgentOutcome, ...],
        missions: tuple[Mission, ...],
    ) -> dict[str, np.ndarray]:
        """Every record array by name (see docs/records.md); ``outcomes`` and ``missions`` in
        the order of the recorder's agent ids."""
        tracks = [self.rows[a] for a in self.agent_ids]
        n_agents = len(tracks)
        n_rows = max((len(track) for track in tracks), default=0)
        # neighbours of each row of each track
        counts = [np.fromiter(map(len, t.neighbours), np.int64, len(t)) for t in tracks]
        n_slots = max([1] + [int(c.max(initial=0)) for c in counts])
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
        nbr_ids = []  # (agent, flat slots, ids) of each agent with neighbours
        for a, track in enumerate(tracks):
            n = len(track)
            if not n:
                continue
            floats, ints, bools = track.columns()
            out["valid"][a, :n] = True
            out["step"][a, :n] = ints[:, 0]
            out["lane_index"][a, :n] = ints[:, 1]
            out["in_junction"][a, :n] = bools[:, 0]
            for j, name in enumerate(STEP_FLOATS):
                out[name][a, :n] = floats[:, j]
            for j, name in enumerate(EVENT_FLAGS):
                out[name][a, :n] = bools[:, 1 + j]
            lane_ids[a][:n] = track.lane_ids
            # Every neighbour of every row at once: row t's k neighbours go to slots 0..k-1.
            rows, count = track.neighbours, counts[a]
            if count.sum() == 0:
                continue
            row_of = np.repeat(np.arange(n), count)
            slot_of = np.arange(len(row_of)) - np.repeat(np.cumsum(count) - count, count)
            # Each neighbour's place in its agent's (rows, slots) plane, flat: one index array
            # per assignment instead of three.
            at = row_of * n_slots + slot_of
            out["nbr_valid"][a].reshape(-1)[at] = True
            values = np.concatenate([nbr.values for nbr in rows])
            for j, name in enumerate(NEIGHBOUR_FLOATS):
                out[f"nbr_{name}"][a].reshape(-1)[at] = values[:, j]
            ids = np.array(list(chain.from_iterable(nbr.ids for nbr in rows)), dtype=str)
            nbr_ids.append((a, at, ids))
        out["lane_id"] = _str_array(lane_ids)
        # As _str_array would make it from nested lists: fixed width of the longest id.
        width = max([1] + [ids.dtype.itemsize // 4 for *_, ids in nbr_ids])
        out["nbr_id"] = np.full(nbr_shape, "", dtype=f"<U{width}")
        for a, at, ids in nbr_ids:
            out["nbr_id"][a].reshape(-1)[at] = ids
        return out


def _str_array(value) -> np.ndarray:
    """Fixed-width unicode array (never object dtype, so loading needs no pickle)."""
    arr = np.array(value, dtype=str)
    return arr if arr.dtype.itemsize else arr.astype("<U1")


def write_npz(path: Path, arrays: dict[str, np.ndarray]) -> None:
    """``np.savez_compressed``-compatible archive with fixed member order and timestamps."""
    with (
        replaced_atomically(Path(path)) as partial,
        zipfile.ZipFile(partial, "w", compression=zipfile.ZIP_DEFLATED) as zf,
    ):
        for name in sorted(arrays):
            buffer = io.BytesIO()
            np.lib.format.write_array(buffer, np.asarray(arrays[name]), allow_pickle=False)
            info = zipfile.ZipInfo(f"{name}.npy", date_time=(1980, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = 0o600 << 16
            zf.writestr(info, buffer.getvalue())
