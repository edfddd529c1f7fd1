import xml.etree.ElementTree as ET

import numpy as np
import pytest

from evaluator.replay_picture import ReplayError, draw_episode
from evaluator.runner.results import record_path
from tests.scoring.builders import AgentSpec, drive, write_record

SVG = "{http://www.w3.org/2000/svg}"


def crash_record(results_dir):
    speeds = np.linspace(2.0, 12.0, 40)
    rows = drive(40, speed=speeds)
    rows["x"] = np.cumsum(speeds) * 0.1
    nbr = np.stack([rows["x"] + 8.0, np.full(40, 3.2)], axis=-1)[:, None, :]
    path = record_path(results_dir, "cut_in_1")
    path.parent.mkdir(parents=True)
    write_record(path, "cut_in_1", [AgentSpec(rows, reason="collision", nbr_xy=nbr)])


def test_picture_shows_path_coloured_by_speed_trails_goal_and_collision(tmp_path):
    crash_record(tmp_path)
    out = draw_episode(tmp_path, "cut_in_1", tmp_path / "p.svg")
    root = ET.parse(out).getroot()
    ego = root.find(f".//{SVG}g[@id='Agent_0']")
    colours = [line.get("stroke") for line in ego.iter(f"{SVG}line")]
    assert len(colours) == 39 and colours[0] != colours[-1]
    titles = [t.text for t in root.iter(f"{SVG}title")]
    assert "Agent_0 goal" in titles
    assert "Agent_0 collision at step 40" in titles
    trails = root.find(f".//{SVG}g[@id='background-trails']")
    assert len(list(trails.iter(f"{SVG}polyline"))) == 1
    assert "collision at step 40" in ET.tostring(root.find(f".//{SVG}g[@id='legend']"), "unicode")


def test_missing_record_is_a_clear_error(tmp_path):
    with pytest.raises(ReplayError, match="no record for nope"):
        draw_episode(tmp_path, "nope", tmp_path / "p.svg")
