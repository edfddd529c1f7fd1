"""`arena replay --format svg`: one episode drawn as SVG from its record, over the scenario's map.

What a participant needs to understand a failure: where the ego drove and how fast, where the
other vehicles went, where the goal was, and where it collided or left the road. Drawing is done
with the simulator's canvas (``sim.render``); this module only decides what to draw.
"""

from __future__ import annotations

import itertools
from html import escape
from pathlib import Path

import numpy as np

from arena.scenario import load_scenario
from evaluator.scoring.record import scalar
from scenarios.picture import stop_lanes
from sim.render import GOAL_COLOUR, SvgCanvas, draw_road
from sim.road import RoadNetwork

# Slow (blue) to fast (red), as fractions of the top speed drawn.
SPEED_COLOURS = ((0.0, (49, 54, 149)), (0.5, (255, 255, 191)), (1.0, (165, 0, 38)))
TRAIL_COLOUR = "#7fd3ff"
EVENT_MARKERS = (("ev_collision", "#d62728", "collision"), ("ev_off_road", "#ff7f0e", "off road"))
MARKER_SIZE_M = 2.5
MARGIN_M = 30.0  # around the mission agents' paths and goals
PICTURE_WIDTH_PX = 1200.0


def episode_svg(rec: dict[str, np.ndarray], scenario_dir: Path | None) -> str:
    top_speed = max(float(np.nanmax(rec["speed"], initial=0.0)), 1.0)  # [m/s]
    canvas = _canvas_with_map(rec, scenario_dir)
    _trails(canvas, rec)
    for a in range(len(rec["agent_ids"])):
        _ego(canvas, rec, a, top_speed)
    _legend(canvas, rec, top_speed, map_drawn=scenario_dir is not None)
    return canvas.to_svg()


def _canvas_with_map(rec: dict[str, np.ndarray], scenario_dir: Path | None) -> SvgCanvas:
    """A canvas around what the mission agents did (their paths and goals), with the road map
    under it when the scenario is at hand."""
    valid = rec["valid"]
    xs = np.concatenate([rec["x"][valid], rec["goal_x"]])
    ys = np.concatenate([rec["y"][valid], rec["goal_y"]])
    extent = max(float(np.ptp(xs)), float(np.ptp(ys)), 1.0) + 2 * MARGIN_M  # [m]
    scale = min(6.0, max(0.5, PICTURE_WIDTH_PX / extent))  # [px/m]
    canvas = SvgCanvas((xs.min(), ys.min(), xs.max(), ys.max()), scale, margin=MARGIN_M)
    if scenario_dir is not None:
        net_path = scenario_dir / load_scenario(scenario_dir).map
        draw_road(canvas, RoadNetwork.load(net_path), stop_lanes(net_path))
    return canvas


def _trails(canvas: SvgCanvas, rec: dict[str, np.ndarray]) -> None:
    """Other vehicles as seen by any mission agent, one line per vehicle id, in step order."""
    paths: dict[str, dict[int, tuple[float, float]]] = {}
    mission = set(rec["agent_ids"].tolist())
    for a, t, k in zip(*np.nonzero(rec["nbr_valid"]), strict=True):
        vehicle = str(rec["nbr_id"][a, t, k])
        if vehicle not in mission:
            point = (float(rec["nbr_x"][a, t, k]), float(rec["nbr_y"][a, t, k]))
            paths.setdefault(vehicle, {})[int(rec["step"][a, t])] = point
    for vehicle in sorted(paths):
        xy = np.array([paths[vehicle][s] for s in sorted(paths[vehicle])])
        if len(xy) > 1:
            canvas.polyline(xy, TRAIL_COLOUR, 0.8, opacity=0.6)


def _speed_colour(fraction: float) -> str:
    fraction = min(max(fraction, 0.0), 1.0)
    for (f0, c0), (f1, c1) in itertools.pairwise(SPEED_COLOURS):
        if fraction <= f1:
            w = (fraction - f0) / (f1 - f0)
            r, g, b = (round(c0[i] + w * (c1[i] - c0[i])) for i in range(3))
            return f"#{r:02x}{g:02x}{b:02x}"
    raise AssertionError("unreachable: SPEED_COLOURS ends at 1.0")


def _ego(canvas: SvgCanvas, rec: dict[str, np.ndarray], a: int, top_speed: float) -> None:
    n = int(rec["steps"][a])
    agent_id = str(rec["agent_ids"][a])
    gx, gy, radius = (float(rec[name][a]) for name in ("goal_x", "goal_y", "goal_radius"))
    canvas.circle(gx, gy, max(radius, 1.0), GOAL_COLOUR, opacity=0.5, stroke="#145214")
    canvas.text(gx, gy + radius + 1.5, f"goal {agent_id}", size=2.5)
    xy = np.column_stack([rec["x"][a, :n], rec["y"][a, :n]])
    for t in range(1, n):
        colour = _speed_colour(float(rec["speed"][a, t]) / top_speed)
        canvas.polyline(xy[t - 1 : t + 1], colour, 1.2)
    if n:
        last = n - 1
        heading = float(rec["heading"][a, last])
        length, width = float(rec["length"][a]), float(rec["width"][a])
        canvas.vehicle(*xy[last], heading, length, width, fill="#ffffff", label=agent_id)
    for flag, colour, label in EVENT_MARKERS:
        for t in np.flatnonzero(rec[flag][a, :n]):
            _cross(canvas, *xy[t], colour)
            canvas.text(*xy[t] - [0.0, 5.0], f"{label} @ step {int(rec['step'][a, t])}", 2.5)


def _cross(canvas: SvgCanvas, x: float, y: float, colour: str) -> None:
    d = MARKER_SIZE_M
    canvas.polyline(np.array([[x - d, y - d], [x + d, y + d]]), colour, 0.8)
    canvas.polyline(np.array([[x - d, y + d], [x + d, y - d]]), colour, 0.8)


def _legend(
    canvas: SvgCanvas, rec: dict[str, np.ndarray], top_speed: float, *, map_drawn: bool
) -> None:
    """A text strip under the drawing, so it never hides the road."""
    lines = [str(scalar(rec["scenario_id"]))]
    lines += [
        f"{rec['agent_ids'][a]}: {rec['done_reason'][a]} at step {int(rec['done_step'][a])}"
        for a in range(len(rec["agent_ids"]))
    ]
    lines.append(f"ego path: blue 0 m/s to red {top_speed:.1f} m/s; light blue: other vehicles")
    lines.append("x: collision (red), off road (orange); green circle: goal")
    if not map_drawn:
        lines.append("map not drawn: the scenario folder was not found (--suite)")
    top = canvas.height
    canvas.height += 12 + 18 * len(lines)
    canvas.elements.append(
        f'<rect x="0" y="{top:.1f}" width="100%" height="{canvas.height - top:.1f}" fill="#fff"/>'
    )
    for i, line in enumerate(lines):
        canvas.elements.append(
            f'<text x="8" y="{top + 20 + 18 * i:.1f}" font-size="14" font-family="sans-serif">'
            f"{escape(line)}</text>"
        )
