"""Generated CommonRoad corpora for build tests: the shipped scenes copied and altered (no real
data beyond the four shipped scenes). Each builder writes one file and returns its path."""

from __future__ import annotations

import copy
import math
import xml.etree.ElementTree as ET
from pathlib import Path

HIGHWAY = "USA_US101-4_1_T-1.xml"  # 2020a, 22 vehicles over 10 s
HIGHWAY_2018 = "USA_US101-3_3_T-1.xml"  # 2018b, 12 vehicles, lane changes
_ID_SHIFT = 900000  # obstacle ids of a second scene of one recording: unlike the first's


def _obstacles(root: ET.Element) -> list[ET.Element]:
    return [
        el
        for el in root
        if el.tag == "dynamicObstacle"
        or (el.tag == "obstacle" and el.findtext("role") == "dynamic")
    ]


def vehicle_ids(path: Path) -> list[str]:
    """The ids of a file's recorded vehicles, in file order (without the ``cr`` prefix)."""
    return [o.get("id") for o in _obstacles(ET.parse(path).getroot())]


def _states(obstacle: ET.Element) -> list[ET.Element]:
    return [obstacle.find("initialState"), *obstacle.findall("trajectory/state")]


def _write(root: ET.Element, path: Path) -> Path:
    ET.ElementTree(root).write(path, encoding="unicode", xml_declaration=True)
    return path


def copy_scene(src: Path, out: Path, benchmark_id: str | None = None, **attrs: str) -> Path:
    """``src`` as ``out`` with a new benchmark id and other root attributes (e.g. ``source``)."""
    root = ET.parse(src).getroot()
    if benchmark_id is not None:
        root.set("benchmarkID", benchmark_id)
    for key, value in attrs.items():
        root.set(key, value)
    return _write(root, out)


def without_trajectories(src: Path, out: Path) -> Path:
    """Every vehicle reduced to its initial state and a set-based occupancy (a prediction
    benchmark): nothing recorded to replay."""
    root = ET.parse(src).getroot()
    root.set("benchmarkID", out.stem)
    for obstacle in _obstacles(root):
        trajectory = obstacle.find("trajectory")
        obstacle.remove(trajectory)
        occupancy = ET.SubElement(obstacle, "occupancySet")
        ET.SubElement(ET.SubElement(occupancy, "occupancy"), "time").text = "1"
    return _write(root, out)


def split_recording(src: Path, folder: Path, location: str, cut: tuple[int, int]) -> list[Path]:
    """One recording cut into two scenes ``<location>_1_T-1`` (steps 0..cut[1]) and
    ``<location>_2_T-1`` (steps cut[0].., its clock restarting at 0 and its obstacle ids
    renumbered), overlapping between the cuts, as CommonRoad cuts NGSIM recordings."""
    first, last = cut
    out = []
    for part, (lo, hi, shift) in enumerate([(0, last, 0), (first, 10**9, first)], start=1):
        root = ET.parse(src).getroot()
        name = f"{location}_{part}_T-1"
        root.set("benchmarkID", name)
        for obstacle in _obstacles(root):
            kept = [s for s in _states(obstacle) if lo <= int(s.findtext("time/exact")) <= hi]
            if len(kept) < 2:
                root.remove(obstacle)
                continue
            for s in kept:
                s.find("time/exact").text = str(int(s.findtext("time/exact")) - shift)
            initial = obstacle.find("initialState")
            trajectory = obstacle.find("trajectory")
            for s in list(trajectory):
                trajectory.remove(s)
            initial_index = list(obstacle).index(initial)
            obstacle.remove(initial)
            new_initial = copy.deepcopy(kept[0])
            new_initial.tag = "initialState"
            obstacle.insert(initial_index, new_initial)
            trajectory.extend(kept[1:])
            if part == 2:
                obstacle.set("id", str(int(obstacle.get("id")) + _ID_SHIFT))
        out.append(_write(root, folder / f"{name}.xml"))
    return out


def with_truck_ahead(src: Path, out: Path, vehicle: str, gap_m: float = 9.0) -> Path:
    """``src`` plus a 20 m truck whose centre drives ``gap_m`` ahead of recorded vehicle
    ``vehicle`` (id without the ``cr`` prefix) along its heading: their boxes overlap at every
    step though the centres are farther apart than a car's length."""
    root = ET.parse(src).getroot()
    root.set("benchmarkID", out.stem)
    original = next(o for o in _obstacles(root) if o.get("id") == vehicle)
    truck = copy.deepcopy(original)
    truck.set("id", str(int(vehicle) + _ID_SHIFT))
    truck.find("type").text = "truck"
    truck.find("shape/rectangle/length").text = "20.0"
    truck.find("shape/rectangle/width").text = "2.6"
    for s in _states(truck):
        h = float(s.findtext("orientation/exact"))
        point = s.find("position/point")
        point.find("x").text = f"{float(point.findtext('x')) + gap_m * math.cos(h):.4f}"
        point.find("y").text = f"{float(point.findtext('y')) + gap_m * math.sin(h):.4f}"
    root.insert(list(root).index(original) + 1, truck)
    return _write(root, out)


def malformed(out: Path) -> Path:
    out.write_text("<commonRoad commonRoadVersion='2020a'><lanelet id='1'><leftBound>")
    return out


def unsupported_version(src: Path, out: Path) -> Path:
    return copy_scene(src, out, out.stem, commonRoadVersion="2017a")


def transformed(
    src: Path,
    out: Path,
    *,
    shift: tuple[float, float] = (0.0, 0.0),
    rotate: float = 0.0,
    time_shift: int = 0,
    slower: int = 1,
    benchmark_id: str | None = None,
) -> Path:
    """``src`` moved rigidly: every point rotated by ``rotate`` [rad] about the origin, then
    shifted by ``shift`` [m]; every orientation turned by ``rotate``; every state's time step
    multiplied by ``slower`` (the same paths driven that many times slower), then delayed by
    ``time_shift``. A georeferenced scene is a shift by UTM-sized offsets; a rotated copy is the
    same scene another way up."""
    root = ET.parse(src).getroot()
    root.set("benchmarkID", benchmark_id or out.stem)
    c, s = math.cos(rotate), math.sin(rotate)
    for point in root.iter("point"):
        x, y = float(point.findtext("x")), float(point.findtext("y"))
        point.find("x").text = f"{c * x - s * y + shift[0]:.4f}"
        point.find("y").text = f"{s * x + c * y + shift[1]:.4f}"
    for obstacle in _obstacles(root):
        for state in _states(obstacle):
            exact = state.find("orientation/exact")
            if exact is not None:
                h = float(exact.text) + rotate
                exact.text = f"{(h + math.pi) % (2 * math.pi) - math.pi:.6f}"
            step = state.find("time/exact")
            step.text = str(int(step.text) * slower + time_shift)
            velocity = state.find("velocity/exact")
            if velocity is not None and slower != 1:
                velocity.text = f"{float(velocity.text) / slower:.4f}"
    return _write(root, out)


def with_road_user(src: Path, out: Path, vehicle: str, kind: str, length: float) -> Path:
    """``src`` with recorded vehicle ``vehicle`` (id without ``cr``) recast as a road user of
    CommonRoad type ``kind`` (``train``, ``bicycle``, ``pedestrian`` ...) of ``length`` metres."""
    root = ET.parse(src).getroot()
    root.set("benchmarkID", out.stem)
    obstacle = next(o for o in _obstacles(root) if o.get("id") == vehicle)
    obstacle.find("type").text = kind
    obstacle.find("shape/rectangle/length").text = f"{length}"
    return _write(root, out)


def with_states(src: Path, out: Path, kind: str, vehicles: int | None = None) -> Path:
    """``src`` with every vehicle's (or the first ``vehicles``') states of another state model:
    ``set-valued`` (positions as rectangles, orientations as intervals, as in a prediction) or
    ``point-mass`` (velocity along x and y, no orientation)."""
    root = ET.parse(src).getroot()
    root.set("benchmarkID", out.stem)
    for obstacle in _obstacles(root)[:vehicles]:
        for state in _states(obstacle):
            orientation = state.find("orientation")
            h = float(orientation.findtext("exact"))
            if kind == "set-valued":
                point = state.find("position/point")
                x, y = float(point.findtext("x")), float(point.findtext("y"))
                position = state.find("position")
                position.remove(point)
                rect = ET.SubElement(position, "rectangle")
                for tag, value in (("length", 1.0), ("width", 1.0)):
                    ET.SubElement(rect, tag).text = str(value)
                centre = ET.SubElement(rect, "center")
                ET.SubElement(centre, "x").text = f"{x:.4f}"
                ET.SubElement(centre, "y").text = f"{y:.4f}"
                orientation.remove(orientation.find("exact"))
                ET.SubElement(orientation, "intervalStart").text = f"{h - 0.1:.4f}"
                ET.SubElement(orientation, "intervalEnd").text = f"{h + 0.1:.4f}"
            elif kind == "point-mass":
                v = float(state.findtext("velocity/exact"))
                state.find("velocity/exact").text = f"{v * math.cos(h):.4f}"
                vy = ET.SubElement(state, "velocityY")
                ET.SubElement(vy, "exact").text = f"{v * math.sin(h):.4f}"
                state.remove(orientation)
            else:
                raise ValueError(kind)
    return _write(root, out)
