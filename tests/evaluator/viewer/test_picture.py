import xml.etree.ElementTree as ET

import numpy as np
import pytest

from evaluator.runner.results import record_path
from evaluator.viewer.export import ReplayFormat, find_record, write_replay
from evaluator.viewer.model import ReplayError
from evaluator.viewer.picture import TRAIL_COLOUR
from sim.render import ROAD_COLOUR
from tests.evaluator.scoring.builders import AgentSpec, drive, write_record
from tests.sim.builders import make_scenario

SVG = "{http://www.w3.org/2000/svg}"


def crash_record(results_dir, scenario_id="cut_in_1"):
    speeds = np.linspace(2.0, 12.0, 40)
    rows = drive(40, speed=speeds, start=(10.0, -1.6))
    rows["x"] = 10.0 + np.cumsum(speeds) * 0.1
    nbr = np.stack([rows["x"] + 8.0, np.full(40, 1.6)], axis=-1)[:, None, :]
    path = record_path(results_dir, scenario_id)
    path.parent.mkdir(parents=True)
    write_record(path, scenario_id, [AgentSpec(rows, reason="collision", nbr_xy=nbr)])


def draw_episode(results_dir, scenario_id, out, suite_dir=None):
    return write_replay(find_record(results_dir, scenario_id), suite_dir, ReplayFormat.svg, out)


def texts(root) -> list[str]:
    return [t.text for t in root.iter(f"{SVG}text")]


def test_picture_shows_path_coloured_by_speed_trails_goal_and_collision(tmp_path):
    crash_record(tmp_path)
    root = ET.parse(draw_episode(tmp_path, "cut_in_1", tmp_path / "p.svg")).getroot()
    strokes = [line.get("stroke") for line in root.iter(f"{SVG}polyline")]
    assert strokes.count(TRAIL_COLOUR) == 1
    speed_colours = [s for s in strokes if s not in (TRAIL_COLOUR, "#d62728")]
    assert len(speed_colours) == 39 and speed_colours[0] != speed_colours[-1]
    assert strokes.count("#d62728") == 2  # the collision cross
    assert "collision @ step 40" in texts(root)
    assert "goal Agent_0" in texts(root)
    assert "Agent_0: collision at step 40" in texts(root)


@pytest.mark.slow
def test_map_is_drawn_when_the_scenario_is_found(tmp_path):
    make_scenario(tmp_path / "suite" / "cut_in_1")
    crash_record(tmp_path / "results")
    out = draw_episode(
        tmp_path / "results", "cut_in_1", tmp_path / "p.svg", suite_dir=tmp_path / "suite"
    )
    root = ET.parse(out).getroot()
    assert ROAD_COLOUR in [p.get("fill") for p in root.iter(f"{SVG}polygon")]
    assert not any("map not drawn" in text for text in texts(root))


def test_missing_record_is_a_clear_error(tmp_path):
    with pytest.raises(ReplayError, match="not a results folder"):
        draw_episode(tmp_path, "nope", tmp_path / "p.svg")
    crash_record(tmp_path)
    with pytest.raises(ReplayError, match="no record for nope"):
        draw_episode(tmp_path, "nope", tmp_path / "p.svg")
