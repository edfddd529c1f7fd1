"""Records a scene: heterogeneous SUMO drivers on a map, every vehicle's trajectory saved.

The scene runs in a ``sumo`` child process (not libsumo: one simulation per process, and the
recording must not disturb a caller's simulation) with floating-car-data output, converted to the
replay trajectory format of :mod:`sim.trajectories`. Data recorded this way is labelled
``recorded`` (never ``naturalistic``).
"""

from __future__ import annotations

import math
import subprocess
import tempfile
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from arena import portable_math
from arena.child_env import HOST_TOOL_VARIABLES, child_environment
from arena.errors import ArenaError
from scenarios.traffic import Routes
from sim.trajectories import Trajectory

STEP_LENGTH = 0.1  # [s]


@dataclass(frozen=True)
class Recording:
    trajectories: dict[str, Trajectory]
    edges: dict[str, tuple[str, ...]]  # normal edges each vehicle drove, in order
    lanes: dict[str, tuple[str, ...]]  # lane id per frame (internal lanes included)


class RecordingError(ArenaError, RuntimeError):
    pass


def record_scene(net_path: Path, routes: Routes, seed: int, duration_s: float) -> Recording:
    """Run ``routes`` on ``net_path`` for ``duration_s`` [s] and return every trajectory."""
    with tempfile.TemporaryDirectory() as tmp:
        rou = Path(tmp) / "scene.rou.xml"
        fcd = Path(tmp) / "fcd.xml"
        rou.write_text(routes.to_xml())
        cmd = [
            "sumo",
            "-n",
            str(net_path),
            "-r",
            str(rou),
            "--step-length",
            str(STEP_LENGTH),
            "--end",
            f"{duration_s:.1f}",
            "--seed",
            str(seed),
            "--lanechange.duration",
            "2.5",
            "--fcd-output",
            str(fcd),
            "--fcd-output.attributes",
            "x,y,angle,speed,lane,type",
            "--collision.action",
            "warn",
            "--no-step-log",
            "true",
            "--no-warnings",
            "true",
        ]
        proc = subprocess.run(
            cmd, capture_output=True, text=True, env=child_environment(inherit=HOST_TOOL_VARIABLES)
        )
        if proc.returncode != 0:
            raise RecordingError(f"sumo failed: {proc.stderr.strip()[-2000:]}")
        return parse_fcd(fcd, _dimensions(routes))


def _dimensions(routes: Routes) -> dict[str, tuple[float, float]]:
    return {
        vt["id"]: (float(vt.get("length", 5.0)), float(vt.get("width", 1.8)))
        for vt in routes.vtypes + routes.special_types
    }


def parse_fcd(path: Path, dims: dict[str, tuple[float, float]]) -> Recording:
    """FCD positions are the front bumper centre and ``angle`` is navigational (degrees, 0 north,
    clockwise): converted to the vehicle centre and our heading convention."""
    rows: dict[str, list[tuple[float, float, float, float, float]]] = {}
    lanes: dict[str, list[str]] = {}
    types: dict[str, str] = {}
    time = 0.0
    for _, elem in ET.iterparse(path, events=("start",)):
        if elem.tag == "timestep":
            time = round(float(elem.get("time")), 1)
        elif elem.tag == "vehicle":
            vid = elem.get("id")
            heading = math.remainder(math.radians(90.0 - float(elem.get("angle"))), math.tau)
            rows.setdefault(vid, []).append(
                (
                    time,
                    float(elem.get("x")),
                    float(elem.get("y")),
                    heading,
                    float(elem.get("speed")),
                )
            )
            lanes.setdefault(vid, []).append(elem.get("lane"))
            types[vid] = elem.get("type")
    trajectories, edges = {}, {}
    for vid, values in rows.items():
        arr = np.asarray(values)
        length, width = dims.get(types[vid].split("@")[0], (4.5, 1.8))
        x = arr[:, 1] - 0.5 * length * portable_math.cos(arr[:, 3])
        y = arr[:, 2] - 0.5 * length * portable_math.sin(arr[:, 3])
        trajectories[vid] = Trajectory(vid, arr[:, 0], x, y, arr[:, 3], arr[:, 4], length, width)
        seq: list[str] = []
        for lane in lanes[vid]:
            edge = lane.rsplit("_", 1)[0]
            if not edge.startswith(":") and (not seq or seq[-1] != edge):
                seq.append(edge)
        edges[vid] = tuple(seq)
    return Recording(trajectories, edges, {k: tuple(v) for k, v in lanes.items()})
