"""Small builders of synthetic episode records (docs/records.md) for scoring and runner tests."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from evaluator.scoring.record import AgentTrack
from evaluator.scoring.simulated import MAX_STEPS, simulated  # noqa: F401  (the tests take them here)

DT = 0.1  # [s]


def drive(
    n: int,
    *,
    speed: float = 10.0,
    heading: float = 0.0,
    start: tuple[float, float] = (0.0, 0.0),
    **columns: float | np.ndarray,
) -> dict[str, np.ndarray]:
    """``n`` rows of an ego driving straight at constant ``speed`` [m/s] along ``heading``
    [rad], centred in a 3.2 m lane limited to 13.89 m/s; ``columns`` override any field with a
    scalar or an ``(n,)`` array."""
    t = np.arange(1, n + 1) * DT
    rows = {
        "x": start[0] + speed * np.cos(heading) * t,
        "y": start[1] + speed * np.sin(heading) * t,
        "heading": np.full(n, heading),
        "speed": np.full(n, speed),
        "vx": np.full(n, speed * np.cos(heading)),
        "vy": np.full(n, speed * np.sin(heading)),
        "lane_offset": np.zeros(n),
        "lane_width": np.full(n, 3.2),
        "lane_heading": np.full(n, heading),
        "speed_limit": np.full(n, 13.89),
        "in_junction": np.zeros(n, bool),
    }
    for name, value in columns.items():
        rows[name] = np.broadcast_to(np.asarray(value, dtype=rows[name].dtype), (n,)).copy()
    return rows


def track(rows: dict[str, np.ndarray], nbr_xy: np.ndarray | None = None) -> AgentTrack:
    """An :class:`AgentTrack` from ``drive`` rows and neighbour centres ``(n, K, 2)`` [m]
    (NaN for an empty slot)."""
    n = len(rows["x"])
    nbr_xy = np.full((n, 1, 2), np.nan) if nbr_xy is None else np.asarray(nbr_xy, float)
    valid = ~np.isnan(nbr_xy[..., 0])
    return AgentTrack(
        **{name: values for name, values in rows.items() if name != "in_junction"},
        in_junction=rows["in_junction"],
        nbr_valid=valid,
        nbr_x=nbr_xy[..., 0],
        nbr_y=nbr_xy[..., 1],
    )


@dataclass
class AgentSpec:
    rows: dict[str, np.ndarray]
    reason: str = "reached_goal"
    done_step: int | None = None  # default: the last driven step
    nbr_xy: np.ndarray | None = None  # (n, K, 2) [m], NaN for empty slots


def record_arrays(
    scenario_id: str, agents: list[AgentSpec], *, dt: float = DT, max_episode_steps: int = 800
) -> dict[str, np.ndarray]:
    """Every array of docs/records.md for ``agents`` (all starting at step 0)."""
    n_agents = len(agents)
    steps = [len(spec.rows["x"]) for spec in agents]
    rows_t = max(steps)
    k = max([1] + [spec.nbr_xy.shape[1] for spec in agents if spec.nbr_xy is not None])
    out: dict[str, np.ndarray] = {
        "format_version": np.array(1),
        "scenario_id": np.array(scenario_id),
        "scenario_hash": np.array("0" * 64),
        "seed": np.array(7),
        "dt": np.array(dt),
        "max_episode_steps": np.array(max_episode_steps),
        "episode_steps": np.array(
            max(spec.done_step or n for spec, n in zip(agents, steps, strict=True))
        ),
        "agent_ids": np.array([f"Agent_{a}" for a in range(n_agents)]),
        "start_step": np.zeros(n_agents, int),
        "steps": np.array(steps),
        "done_step": np.array([spec.done_step or n for spec, n in zip(agents, steps, strict=True)]),
        "done_reason": np.array([spec.reason for spec in agents]),
        "reached_goal": np.array([spec.reason == "reached_goal" for spec in agents]),
        "length": np.full(n_agents, 4.5),
        "width": np.full(n_agents, 1.8),
        "goal_x": np.array([spec.rows["x"][-1] if len(spec.rows["x"]) else 0.0 for spec in agents]),
        "goal_y": np.array([spec.rows["y"][-1] if len(spec.rows["y"]) else 0.0 for spec in agents]),
        "goal_radius": np.full(n_agents, 2.0),
        "valid": np.zeros((n_agents, rows_t), bool),
        "step": np.zeros((n_agents, rows_t), int),
        "lane_id": np.full((n_agents, rows_t), "", dtype="<U16"),
        "lane_index": np.zeros((n_agents, rows_t), int),
    }
    for name in drive(0):
        out[name] = np.full((n_agents, rows_t), False if name == "in_junction" else np.nan)
    for event in ("collision", "off_road", "off_route", "on_shoulder", "wrong_way"):
        out[f"ev_{event}"] = np.zeros((n_agents, rows_t), bool)
    out["ev_not_moving"] = np.zeros((n_agents, rows_t), bool)
    out["ev_reached_goal"] = np.zeros((n_agents, rows_t), bool)
    out["nbr_valid"] = np.zeros((n_agents, rows_t, k), bool)
    out["nbr_id"] = np.full((n_agents, rows_t, k), "", dtype="<U16")
    for name in ("x", "y", "heading", "speed", "length", "width"):
        out[f"nbr_{name}"] = np.full((n_agents, rows_t, k), np.nan)
    for a, (spec, n) in enumerate(zip(agents, steps, strict=True)):
        out["valid"][a, :n] = True
        out["step"][a, :n] = np.arange(1, n + 1)
        out["lane_id"][a, :n] = "E0_0"
        for name, values in spec.rows.items():
            out[name][a, :n] = values
        if spec.reason == "collision" and n:
            out["ev_collision"][a, n - 1] = True
        if spec.nbr_xy is not None:
            filled = ~np.isnan(spec.nbr_xy[..., 0])
            width = spec.nbr_xy.shape[1]
            out["nbr_valid"][a, :n, :width] = filled
            out["nbr_x"][a, :n, :width] = spec.nbr_xy[..., 0]
            out["nbr_y"][a, :n, :width] = spec.nbr_xy[..., 1]
            out["nbr_heading"][a, :n, :width] = np.where(filled, 0.0, np.nan)
            out["nbr_speed"][a, :n, :width] = np.where(filled, 5.0, np.nan)
            out["nbr_id"][a, :n, :width] = np.where(filled, "bg", "")
    return out


def write_record(path: Path, scenario_id: str, agents: list[AgentSpec], **kwargs) -> Path:
    np.savez_compressed(path, **record_arrays(scenario_id, agents, **kwargs))
    return Path(path)
