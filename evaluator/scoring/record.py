"""Reading episode records (``docs/records.md``) into the arrays the metric terms use."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from arena.errors import RecordError
from arena.outcome import AgentOutcome
from arena.record_format import FORMAT_VERSION, STEP_FLOATS


@dataclass(frozen=True)
class AgentTrack:
    """One mission agent's driven rows: per-step arrays ``(n,)``, neighbours ``(n, K)``."""

    x: np.ndarray  # [m]
    y: np.ndarray  # [m]
    heading: np.ndarray  # [rad]
    speed: np.ndarray  # [m/s]
    vx: np.ndarray  # [m/s]
    vy: np.ndarray  # [m/s]
    lane_offset: np.ndarray  # [m], left positive
    lane_width: np.ndarray  # [m]
    lane_heading: np.ndarray  # [rad]
    speed_limit: np.ndarray  # [m/s]
    in_junction: np.ndarray  # bool
    nbr_valid: np.ndarray  # (n, K) bool
    nbr_x: np.ndarray  # (n, K) [m]
    nbr_y: np.ndarray  # (n, K) [m]


@dataclass(frozen=True)
class EpisodeRecord:
    scenario_id: str
    scenario_hash: str
    dt: float  # [s]
    max_episode_steps: int
    episode_steps: int
    agents: tuple[AgentOutcome, ...]
    tracks: tuple[AgentTrack, ...]
    goals: tuple[tuple[float, float], ...]  # [m] each mission's goal centre


def read_arrays(path: Path) -> dict[str, np.ndarray]:
    """Every array of the record at ``path``, by name (no pickle)."""
    try:
        with np.load(Path(path), allow_pickle=False) as data:
            return {name: data[name] for name in data.files}
    except (OSError, ValueError, EOFError) as exc:
        raise RecordError(f"{path}: not a readable episode record: {exc}") from exc


def load_record(path: Path) -> EpisodeRecord:
    arrays = read_arrays(path)
    try:
        return _parse(arrays)
    except KeyError as exc:
        raise RecordError(f"{path}: missing array {exc}") from None
    except RecordError as exc:
        raise RecordError(f"{path}: {exc}") from None


def scalar(array: np.ndarray) -> int | float | str | bool:
    """The value of a metadata array: 0-d per the format; a 1-element array is accepted too
    (``np.ascontiguousarray`` in a writer turns 0-d into shape (1,))."""
    if array.size != 1:
        raise RecordError(f"metadata array of shape {array.shape}, expected a single value")
    return array.reshape(()).item()


def _parse(arrays: dict[str, np.ndarray]) -> EpisodeRecord:
    version = scalar(arrays["format_version"])
    if version != FORMAT_VERSION:
        raise RecordError(f"format_version {version}, expected {FORMAT_VERSION}")
    steps = arrays["steps"].astype(int)
    agents = tuple(
        AgentOutcome(
            id=str(arrays["agent_ids"][a]),
            reached_goal=bool(arrays["reached_goal"][a]),
            reason=str(arrays["done_reason"][a]),
            steps=int(steps[a]),
            done_step=int(arrays["done_step"][a]),
        )
        for a in range(len(steps))
    )
    tracks = tuple(_track(arrays, a, int(n)) for a, n in enumerate(steps))
    return EpisodeRecord(
        scenario_id=str(scalar(arrays["scenario_id"])),
        scenario_hash=str(scalar(arrays["scenario_hash"])),
        dt=float(scalar(arrays["dt"])),
        max_episode_steps=int(scalar(arrays["max_episode_steps"])),
        episode_steps=int(scalar(arrays["episode_steps"])),
        agents=agents,
        tracks=tracks,
        goals=tuple(
            (float(arrays["goal_x"][a]), float(arrays["goal_y"][a])) for a in range(len(steps))
        ),
    )


def _track(arrays: dict[str, np.ndarray], agent: int, n: int) -> AgentTrack:
    valid = arrays["valid"][agent]
    if n > valid.shape[0] or not valid[:n].all() or valid[n:].any():
        raise RecordError(f"agent {agent}: `valid` does not match steps={n}")
    fields = {name: arrays[name][agent, :n].astype(float) for name in STEP_FLOATS}
    for name, values in fields.items():
        if not np.isfinite(values).all():
            raise RecordError(f"agent {agent}: non-finite `{name}` on a driven row")
    nbr_valid = arrays["nbr_valid"][agent, :n].astype(bool)
    return AgentTrack(
        **fields,
        in_junction=arrays["in_junction"][agent, :n].astype(bool),
        nbr_valid=nbr_valid,
        nbr_x=np.where(nbr_valid, arrays["nbr_x"][agent, :n], np.nan),
        nbr_y=np.where(nbr_valid, arrays["nbr_y"][agent, :n], np.nan),
    )
