"""`arena replay`: one episode drawn as SVG from its record, over the scenario's map.

What a participant needs to understand a failure: where the ego drove and how fast, where the
other vehicles went, where the goal was, and where it collided or left the road.
"""

from __future__ import annotations

import itertools
from pathlib import Path
from xml.sax.saxutils import escape

import numpy as np

from evaluator.runner.results import record_path
from evaluator.scoring.record import scalar

MARGIN_M = 15.0  # around the drawn episode [m]
PIXELS_PER_M = 4.0
# Slow (blue) to fast (red), as fractions of the top speed drawn.
SPEED_COLOURS = ((0.0, (49, 54, 149)), (0.5, (255, 255, 191)), (1.0, (165, 0, 38)))
EVENT_MARKERS = (("ev_collision", "#d62728", "collision"), ("ev_off_road", "#ff7f0e", "off road"))


class ReplayError(ValueError):
    pass


def draw_episode(
    results_dir: Path, scenario_id: str, out: Path, *, suite_dir: Path | None = None
) -> Path:
    path = record_path(results_dir, scenario_id)
    if not path.exists():
        raise ReplayError(f"no record for {scenario_id} in {results_dir}")
    with np.load(path, allow_pickle=False) as data:
        rec = {name: data[name] for name in data.files}
    scenario_dir = Path(suite_dir) / scenario_id if suite_dir is not None else None
    Path(out).write_text(episode_svg(rec, scenario_dir))
    return Path(out)


def episode_svg(rec: dict[str, np.ndarray], scenario_dir: Path | None) -> str:
    valid = rec["valid"]
    nbr = rec["nbr_valid"]
    xs = np.concatenate([rec["x"][valid], rec["nbr_x"][nbr], rec["goal_x"]])
    ys = np.concatenate([rec["y"][valid], rec["nbr_y"][nbr], rec["goal_y"]])
    view = _View(xs.min() - MARGIN_M, ys.min() - MARGIN_M, xs.max() + MARGIN_M, ys.max() + MARGIN_M)
    top_speed = max(float(np.nanmax(rec["speed"], initial=0.0)), 1.0)  # [m/s]
    layers = [_map_layer(scenario_dir, view), _trails(rec, view)]
    for a in range(len(rec["agent_ids"])):
        layers.append(_ego(rec, a, view, top_speed))
    layers.append(_legend(rec, view, top_speed))
    width, height = view.size
    return (
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{width:.0f}" height="{height:.0f}" '
        f'viewBox="0 0 {width:.1f} {height:.1f}" font-family="sans-serif">\n'
        f'<rect width="100%" height="100%" fill="#f4f4f0"/>\n' + "\n".join(layers) + "\n</svg>\n"
    )


class _View:
    """Map metres to SVG pixels, y up."""

    def __init__(self, x0: float, y0: float, x1: float, y1: float) -> None:
        self.x0, self.y0, self.x1, self.y1 = x0, y0, x1, y1

    @property
    def size(self) -> tuple[float, float]:
        return ((self.x1 - self.x0) * PIXELS_PER_M, (self.y1 - self.y0) * PIXELS_PER_M)

    def point(self, x: float, y: float) -> str:
        px, py = self.xy(x, y)
        return f"{px:.1f},{py:.1f}"

    def xy(self, x: float, y: float) -> tuple[float, float]:
        return (x - self.x0) * PIXELS_PER_M, (self.y1 - y) * PIXELS_PER_M


def _map_layer(scenario_dir: Path | None, view: _View) -> str:
    """Lane shapes from the scenario's map; nothing when the scenario folder is not at hand."""
    if scenario_dir is None or not (scenario_dir / "scenario.json").exists():
        return "<!-- map not available: the scenario folder was not found -->"
    from sim.render import lane_polygons  # the simulator's own map geometry

    from scenarios.schema import load_scenario

    scenario = load_scenario(scenario_dir)
    shapes = []
    for polygon in lane_polygons(scenario_dir / scenario.map):
        points = " ".join(view.point(x, y) for x, y in polygon)
        shapes.append(f'<polygon points="{points}" fill="#d9d9d6" stroke="#ffffff" />')
    return '<g id="map">' + "".join(shapes) + "</g>"


def _trails(rec: dict[str, np.ndarray], view: _View) -> str:
    """Background vehicles seen by any agent, one grey polyline per vehicle id."""
    paths: dict[str, dict[int, tuple[float, float]]] = {}
    mission = set(rec["agent_ids"].tolist())
    ids, steps = rec["nbr_id"], rec["step"]
    for a, t, k in zip(*np.nonzero(rec["nbr_valid"]), strict=True):
        vehicle = str(ids[a, t, k])
        if vehicle not in mission:
            paths.setdefault(vehicle, {})[int(steps[a, t])] = (
                float(rec["nbr_x"][a, t, k]),
                float(rec["nbr_y"][a, t, k]),
            )
    lines = []
    for vehicle in sorted(paths):
        points = " ".join(view.point(*paths[vehicle][s]) for s in sorted(paths[vehicle]))
        lines.append(
            f'<polyline points="{points}" fill="none" stroke="#8a8a8a" stroke-width="2" '
            f'stroke-opacity="0.6"><title>{escape(vehicle)}</title></polyline>'
        )
    return '<g id="background-trails">' + "".join(lines) + "</g>"


def _speed_colour(fraction: float) -> str:
    fraction = min(max(fraction, 0.0), 1.0)
    for (f0, c0), (f1, c1) in itertools.pairwise(SPEED_COLOURS):
        if fraction <= f1:
            w = (fraction - f0) / (f1 - f0)
            r, g, b = (round(c0[i] + w * (c1[i] - c0[i])) for i in range(3))
            return f"#{r:02x}{g:02x}{b:02x}"
    raise AssertionError("unreachable: SPEED_COLOURS ends at 1.0")


def _cross(cx: float, cy: float, colour: str, title: str) -> str:
    d = f"M{cx - 8:.1f},{cy - 8:.1f} L{cx + 8:.1f},{cy + 8:.1f} "
    d += f"M{cx - 8:.1f},{cy + 8:.1f} L{cx + 8:.1f},{cy - 8:.1f}"
    return f'<path d="{d}" stroke="{colour}" stroke-width="4"><title>{title}</title></path>'


def _ego(rec: dict[str, np.ndarray], a: int, view: _View, top_speed: float) -> str:
    n = int(rec["steps"][a])
    agent_id = escape(str(rec["agent_ids"][a]))
    xy = [
        view.xy(float(x), float(y)) for x, y in zip(rec["x"][a, :n], rec["y"][a, :n], strict=True)
    ]
    parts = [f'<g id="{agent_id}">']
    gx, gy = view.xy(float(rec["goal_x"][a]), float(rec["goal_y"][a]))
    radius = float(rec["goal_radius"][a]) * PIXELS_PER_M
    parts.append(
        f'<circle cx="{gx:.1f}" cy="{gy:.1f}" r="{radius:.1f}" fill="#2ca02c" fill-opacity="0.3" '
        f'stroke="#2ca02c" stroke-width="2"><title>{agent_id} goal</title></circle>'
    )
    for t in range(1, n):
        (x0, y0), (x1, y1) = xy[t - 1], xy[t]
        colour = _speed_colour(float(rec["speed"][a, t]) / top_speed)
        parts.append(
            f'<line x1="{x0:.1f}" y1="{y0:.1f}" x2="{x1:.1f}" y2="{y1:.1f}" stroke="{colour}" '
            'stroke-width="4" stroke-linecap="round"/>'
        )
    if n:
        parts.append(
            f'<circle cx="{xy[0][0]:.1f}" cy="{xy[0][1]:.1f}" r="5" fill="#000">'
            f"<title>{agent_id} start</title></circle>"
        )
    for flag, colour, label in EVENT_MARKERS:
        for t in np.flatnonzero(rec[flag][a, :n]):
            step = int(rec["step"][a, t])
            parts.append(_cross(*xy[t], colour, f"{agent_id} {label} at step {step}"))
    parts.append("</g>")
    return "".join(parts)


def _legend(rec: dict[str, np.ndarray], view: _View, top_speed: float) -> str:
    lines = [str(scalar(rec["scenario_id"]))]
    for a in range(len(rec["agent_ids"])):
        lines.append(
            f"{rec['agent_ids'][a]}: {rec['done_reason'][a]} at step {int(rec['done_step'][a])}"
        )
    lines.append(f"ego speed: blue 0 m/s .. red {top_speed:.1f} m/s; grey: other vehicles")
    lines.append("red x: collision, orange x: off road, green: goal")
    text = "".join(
        f'<text x="10" y="{20 + 18 * i}" font-size="14">{escape(line)}</text>'
        for i, line in enumerate(lines)
    )
    return f'<g id="legend">{text}</g>'
