from __future__ import annotations

import math

import numpy as np
import pytest

from scenarios.recorded.commonroad import CommonRoadImportError, read_commonroad
from scenarios.recorded.ngsim import FOOT, NgsimFormatError, headings_from_positions, read_ngsim

NGSIM_HEADER = "Vehicle_ID,Frame_ID,Total_Frames,Local_X,Local_Y,v_Length,v_Width,v_Vel,Lane_ID\n"


def write_ngsim(path, rows) -> None:
    path.write_text(NGSIM_HEADER + "".join(",".join(map(str, r)) + "\n" for r in rows))


def test_ngsim_converts_feet_and_takes_heading_along_the_road(tmp_path):
    # Vehicle 7 drives straight along Local_Y at 50 ft/s (5 ft per 0.1 s frame) in lane 2;
    # vehicle 9 drifts right (Local_X grows) while moving forward: heading is negative.
    rows = [(7, 100 + i, 50, 12.0, 200.0 + 5 * i, 15.0, 6.0, 50.0, 2) for i in range(5)]
    rows += [(9, 102 + i, 50, 24.0 + i, 100.0 + 5 * i, 16.0, 6.5, 51.0, 3) for i in range(4)]
    write_ngsim(tmp_path / "ngsim.csv", rows)
    a, b = read_ngsim(tmp_path / "ngsim.csv")
    assert a.vehicle_id == "7" and b.vehicle_id == "9"
    assert a.length == pytest.approx(15 * FOOT) and a.width == pytest.approx(6 * FOOT)
    assert np.allclose(a.speed, 50 * FOOT)
    assert np.allclose(a.time, [0.0, 0.1, 0.2, 0.3, 0.4]) and np.allclose(b.time[0], 0.2)
    assert np.allclose(a.heading, 0.0)
    # Centre = front centre moved back half a length along the road; y = -Local_X.
    assert a.x[0] == pytest.approx(200 * FOOT - 7.5 * FOOT)
    assert a.y[0] == pytest.approx(-12 * FOOT)
    assert np.allclose(np.diff(a.x), 5 * FOOT)
    assert np.allclose(b.heading, -math.atan2(1.0, 5.0))


def test_ngsim_keeps_the_longest_consecutive_run_and_rejects_missing_columns(tmp_path):
    rows = [(3, f, 50, 10.0, 5.0 * f, 14.0, 6.0, 30.0, 1) for f in (1, 2, 5, 6, 7)]
    write_ngsim(tmp_path / "gap.csv", rows)
    (tr,) = read_ngsim(tmp_path / "gap.csv")
    assert len(tr.time) == 3 and tr.time[0] == pytest.approx(0.4)
    (tmp_path / "bad.csv").write_text("Vehicle_ID,Frame_ID\n1,1\n")
    with pytest.raises(NgsimFormatError, match="Local_X"):
        read_ngsim(tmp_path / "bad.csv")


def test_headings_hold_while_standing_still():
    h = headings_from_positions(np.array([0.0, 0.0, 0.0, 1.0]), np.array([0.0, 1.0, 1.0, 1.0]))
    assert np.allclose(h, [math.pi / 2, math.pi / 2, 0.0, 0.0])


COMMONROAD = """<?xml version='1.0' encoding='UTF-8'?>
<commonRoad timeStepSize="0.2" commonRoadVersion="2020a" author="t" affiliation="t" source="t"
  benchmarkID="DEU_Test-1_1_T-1" date="2020-01-01">
  <location><geoNameId>-999</geoNameId><gpsLatitude>999</gpsLatitude>
    <gpsLongitude>999</gpsLongitude></location>
  <scenarioTags><highway/></scenarioTags>
  <dynamicObstacle id="10">
    <type>car</type>
    <shape><rectangle><length>4.5</length><width>1.8</width></rectangle></shape>
    <initialState>
      <position><point><x>0.0</x><y>0.0</y></point></position>
      <orientation><exact>0.5</exact></orientation>
      <time><exact>0</exact></time>
      <velocity><exact>10.0</exact></velocity>
      <acceleration><exact>0.0</exact></acceleration>
      <yawRate><exact>0.0</exact></yawRate>
      <slipAngle><exact>0.0</exact></slipAngle>
    </initialState>
    <trajectory>
      <state><position><point><x>1.755</x><y>0.959</y></point></position>
        <orientation><exact>0.5</exact></orientation><time><exact>1</exact></time>
        <velocity><exact>10.0</exact></velocity></state>
      <state><position><point><x>3.51</x><y>1.918</y></point></position>
        <orientation><exact>0.6</exact></orientation><time><exact>2</exact></time>
        <velocity><exact>12.0</exact></velocity></state>
    </trajectory>
  </dynamicObstacle>
</commonRoad>
"""


def test_commonroad_obstacles_become_trajectories_resampled_to_tenth_seconds(tmp_path):
    (tmp_path / "scene.xml").write_text(COMMONROAD)
    (tr,) = read_commonroad(tmp_path / "scene.xml")
    assert tr.vehicle_id == "cr10" and (tr.length, tr.width) == (4.5, 1.8)
    assert np.allclose(tr.time, [0.0, 0.1, 0.2, 0.3, 0.4])
    assert np.allclose(tr.x, [0.0, 0.8775, 1.755, 2.6325, 3.51])
    assert np.allclose(tr.heading, [0.5, 0.5, 0.5, 0.55, 0.6])
    assert np.allclose(tr.speed[-1], 12.0)


def test_commonroad_garbage_is_a_clear_error(tmp_path):
    (tmp_path / "bad.xml").write_text("<commonRoad>")
    with pytest.raises(CommonRoadImportError, match="not a readable CommonRoad"):
        read_commonroad(tmp_path / "bad.xml")
