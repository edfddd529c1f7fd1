"""Importer for CommonRoad scenario XML (2020a) into the replay trajectory format, via
``commonroad-io``.

Every dynamic obstacle with a trajectory prediction becomes one trajectory: CommonRoad positions
are already the shape centre in metres and orientations are radians counter-clockwise from +x, as
ours. Scenarios stepped at another rate than 0.1 s are resampled by linear interpolation.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from sim.trajectories import Trajectory

STEP_S = 0.1  # [s]


class CommonRoadImportError(ValueError):
    pass


def read_commonroad(path: Path) -> list[Trajectory]:
    from commonroad.common.file_reader import CommonRoadFileReader  # heavy; only when importing

    try:
        scenario, _ = CommonRoadFileReader(filename_2020a=str(path)).open()
    except Exception as exc:  # commonroad-io raises assorted errors on malformed files
        raise CommonRoadImportError(f"{path}: not a readable CommonRoad scenario: {exc}") from exc
    dt = float(scenario.dt)
    out = []
    for obstacle in sorted(scenario.dynamic_obstacles, key=lambda o: o.obstacle_id):
        prediction = getattr(obstacle, "prediction", None)
        trajectory = getattr(prediction, "trajectory", None)
        states = [obstacle.initial_state, *(trajectory.state_list if trajectory else [])]
        if len(states) < 2:
            continue
        t = np.array([s.time_step * dt for s in states], dtype=float)
        xy = np.array([s.position for s in states], dtype=float)
        heading = np.unwrap([float(s.orientation) for s in states])
        speed = np.array([float(getattr(s, "velocity", 0.0) or 0.0) for s in states])
        shape = obstacle.obstacle_shape
        length = float(getattr(shape, "length", 4.5))
        width = float(getattr(shape, "width", 1.8))
        grid = np.round(np.arange(t[0], t[-1] + 1e-9, STEP_S), 1)
        h = np.interp(grid, t, heading)
        out.append(
            Trajectory(
                vehicle_id=f"cr{obstacle.obstacle_id}",
                time=grid,
                x=np.interp(grid, t, xy[:, 0]),
                y=np.interp(grid, t, xy[:, 1]),
                heading=(h + np.pi) % (2 * np.pi) - np.pi,
                speed=np.interp(grid, t, speed),
                length=length,
                width=width,
            )
        )
    return out
