"""The compiled per-step core gives the pure-Python reference's bits (``sim/compiled.py``).

Each compiled function against the Python it replaces, in this process (the reference runs where
its module's switch, the compiled module it holds, is None), on points and states scattered over
public maps; then whole episodes of the public suite in two processes, one with
``ARENA_PURE_PYTHON=1``: the same record bytes and the same observations, in the dict formats and
the arrays format (the fast tier a few scenarios briefly, the integration tier every one).
"""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import sim.events
import sim.observation_record
import sim.road.centrelines
import sim.road.lane
import sim.road.network
import sim.road.waypoints
import sim.traffic
import sim.vehicle.states
from arena.scenario import load_scenario
from arena.suite import SHIPPED_PUBLIC_DIR
from sim.compiled import MODULES, PURE_PYTHON_VARIABLE, compiled, core_status
from sim.events import Events, collisions
from sim.interface import AgentInterface
from sim.mission_vehicle import Kinematics, MissionVehicle
from sim.observation_arrays import ObservationLayout
from sim.observation_record import ObservationRecord
from sim.road.waypoints import path_starts, waypoint_arrays
from sim.vehicle import Pose
from sim.vehicle.states import VehicleStates
from tests.sim.test_road import MAPS, beside, shipped_road

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(autouse=True, scope="module")
def _built():
    assert core_status() == "compiled", (
        f"the compiled core is not built ({core_status()}): pip install -e . builds it"
    )


def _bits(*values) -> bytes:
    return np.array(values, dtype=np.float64).tobytes()  # tells -0.0 from 0.0, NaN from NaN


def _position(p) -> tuple:
    return p.lane.id, p.segment, _bits(p.s, p.t, p.heading, p.distance)


@pytest.mark.parametrize("scenario_id", MAPS)
def test_nearest_lane_and_projection_are_the_reference_bit_for_bit(scenario_id, monkeypatch):
    # Points on and beside every lane, between lanes (ties), past lane ends, in junctions (the
    # heading chooses among overlapping lanes) and far off the road (the tree answers).
    road = shipped_road(scenario_id)
    rng = np.random.default_rng(21)
    points = []
    for lane in road.lanes.values():
        s = np.concatenate([lane.cumulative_s, rng.uniform(-3.0, lane.length + 3.0, 30)])
        offset = rng.uniform(-3.0, 3.0, len(s)) * lane.width
        offset[::4] = lane.width / 2
        xs, ys, heading = beside(lane, s, offset)
        heading = heading + rng.normal(0.0, 0.6, len(s))
        points += zip(xs.tolist(), ys.tolist(), heading.tolist(), strict=True)
    xmin, ymin, xmax, ymax = road.bounds
    far = rng.uniform([xmin - 30, ymin - 30], [xmax + 30, ymax + 30], (200, 2)).tolist()
    points += [(x, y, 0.5) for x, y in far]

    def answers():
        found = []
        for x, y, h in points:
            found.append(_position(road.nearest_lane(x, y, h)))
            found.append(_position(road.nearest_lane(x, y)))
        for lane in road.lanes.values():  # short lanes by their loop, long ones by their grid
            found += [_bits(*lane.project(x, y)) for x, y, _ in points[::7]]
        return found

    compiled = answers()
    monkeypatch.setattr(sim.road.network, "_lane_search", None)
    monkeypatch.setattr(sim.road.lane, "_lane_search", None)
    assert compiled == answers()


def _random_states(rng, n: int, spread: float) -> VehicleStates:
    values = np.column_stack(
        [
            rng.uniform(-spread, spread, (n, 2)),
            rng.uniform(-4.0, 4.0, n),
            rng.uniform(0.0, 20.0, n),
            rng.uniform(3.0, 6.0, n),
            rng.uniform(1.5, 2.6, n),
        ]
    )
    values[1::5, :2] = values[::5, :2][: len(values[1::5])]  # some at equal distances
    return VehicleStates.of([f"v{i}" for i in range(n)], values, [f"l{i}" for i in range(n)])


def test_neighbours_and_collisions_are_the_reference_bit_for_bit(monkeypatch):
    rng = np.random.default_rng(3)
    cases = [_random_states(rng, int(rng.integers(0, 30)), 12.0) for _ in range(300)]

    def answers():
        found = []
        for i, states in enumerate(cases):
            near, distance = states.nearest_first(0.3 * i % 5, -1.0, 10.0)
            found.append((near.ids, near.lane_id, near.values.tobytes(), distance.tobytes()))
            for d in (distance, None):
                found.append(collisions(0.0, 0.0, 0.1 * i, 4.6, 1.9, near, d))
        return found

    compiled = answers()
    assert sum(1 for f in compiled[1::3] if f) > 50  # many collisions among them
    monkeypatch.setattr(sim.vehicle.states, "_neighbours", None)
    monkeypatch.setattr(sim.events, "_boxes", None)
    assert compiled == answers()


class _Report(sim.traffic.SumoTraffic):
    """SumoTraffic's reading of a context report, without starting SUMO (its report given)."""

    def __init__(self, dims):
        self._dims, self._vars = dict(dims), [0x42, 0x43, 0x40, 0x51]

    def _measure(self, vid):
        size = self._dims[vid] = (2.25, 4.5, 1.8)  # as SUMO's answer for its own vehicles
        return size


def test_states_from_sumos_report_are_the_reference_bit_for_bit(monkeypatch):
    rng = np.random.default_rng(9)
    reports = []
    for _ in range(200):
        ids = [f"bg{int(k)}" for k in rng.choice(500, int(rng.integers(0, 25)), replace=False)]
        report = {
            v: {
                0x42: tuple(rng.uniform(-500.0, 500.0, 2).tolist()),
                0x43: float(rng.choice([0.0, 90.0, 180.0, 270.0, 360.0, rng.uniform(0, 360)])),
                0x40: float(rng.uniform(0.0, 30.0)),
                0x51: f"e{v}_0",
            }
            for v in ["ego", *ids]
        }
        reports.append(report)

    def answers():
        traffic = _Report({"ego": (2.0, 4.0, 1.8), "bg7": (2.5, 5.0, 2.0)})
        found = []
        for i, report in enumerate(reports):
            traffic._around = {"ego": report}
            states = traffic.vehicles_around("ego", {"bg1", "bg2"})
            found.append((states.ids, states.lane_id, states.values.tobytes()))
            # read and ordered in one: about a third of them within the radius
            near, distance = traffic.vehicles_within("ego", {"bg1"}, 4.0 * i, -30.0, 400.0)
            found.append((near.ids, near.lane_id, near.values.tobytes(), distance.tobytes()))
        return found

    compiled = answers()
    within = compiled[1::2]
    assert sum(len(f[0]) for f in within) > 500 and any(not f[0] for f in within)
    monkeypatch.setattr(sim.traffic, "_neighbours", None)
    monkeypatch.setattr(sim.vehicle.states, "_neighbours", None)
    assert compiled == answers()


@pytest.mark.parametrize("scenario_id", MAPS)
def test_waypoint_sampling_is_the_reference_bit_for_bit(scenario_id, monkeypatch):
    road = shipped_road(scenario_id)
    rng = np.random.default_rng(13)
    edges = [lane.edge_id for lane in road.lanes.values() if not lane.is_internal]
    route = tuple(dict.fromkeys(edges))
    queries = []
    for lane in road.lanes.values():
        s = rng.uniform(0.0, lane.length, 4)
        xs, ys, _ = beside(lane, s, rng.uniform(-0.4, 0.4, 4) * lane.width)
        queries += [(x, y) for x, y in zip(xs.tolist(), ys.tolist(), strict=True)]

    def answers():
        found = []
        for x, y in queries:
            position = road.nearest_lane(x, y)
            starts = path_starts(road, position, x, y, route, 4)
            for n in (1, 20, 50):
                arrays = waypoint_arrays(road, starts, route, n)
                found.append((arrays.counts, arrays.values.tobytes(), arrays.pieces))
        return found

    compiled = answers()
    monkeypatch.setattr(sim.road.waypoints, "_sampling", None)
    monkeypatch.setattr(sim.road.centrelines, "_sampling", None)
    assert compiled == answers()


def test_observation_records_are_the_reference_bytes(monkeypatch):
    # Whole observations: the head (pose, kinematics, lane, events), neighbours fewer and more
    # than the slots, with SUMO's lanes and without (the nearest lane's), and waypoint paths
    # full and cut short by a dead end.
    scenario_id = "p000_left_turn_t_low"
    road = shipped_road(scenario_id)
    mission = load_scenario(SHIPPED_PUBLIC_DIR / scenario_id).missions[0]
    interface = AgentInterface(max_neighbours=8, waypoints_per_path=30, max_waypoint_paths=3)
    rng = np.random.default_rng(17)
    lanes = list(road.lanes.values())
    (xmin, ymin, xmax, ymax), route = road.bounds, tuple(road.edges)
    cases = []
    for step in range(150):
        states = _random_states(rng, int(rng.integers(0, 14)), 1.0)
        states.values[:, :2] = rng.uniform([xmin, ymin], [xmax, ymax], (len(states), 2))
        states.lane_id[:] = [lanes[k].id if k % 3 else "" for k in range(len(states))]
        vehicle = MissionVehicle.from_mission(mission)
        x, y = rng.uniform([xmin, ymin], [xmax, ymax]).tolist()
        heading, speed, steering, distance = rng.uniform(-4.0, 30.0, 4).tolist()
        vehicle.pose = Pose(x, y, heading, speed, steering)
        pairs = rng.normal(0.0, 10.0, (3, 2)).tolist()
        vehicle.kinematics = Kinematics(*map(tuple, pairs), *rng.normal(0.0, 3.0, 3).tolist())
        vehicle.distance_travelled = distance * step
        flags = (rng.uniform(size=8) < 0.3).tolist()
        events = Events(("v1", "v2") if flags[0] else (), *flags[1:])
        position = road.nearest_lane(x, y)
        starts = path_starts(road, position, x, y, route, interface.max_waypoint_paths)
        waypoints = waypoint_arrays(road, starts, route, interface.waypoints_per_path)
        cases.append((vehicle, step, position, events, states, waypoints))

    def answers():
        record = ObservationRecord(ObservationLayout(interface))
        found = []
        for vehicle, step, position, events, states, waypoints in cases:
            observation = record.write(
                vehicle=vehicle,
                step=step,
                dt=0.1,
                lane=position,
                events=events,
                neighbours=states,
                road=road,
                waypoints=waypoints,
                rasters=None,
                done=False,
            )
            found.append(bytes(observation.record))
        return found

    compiled = answers()
    assert any(sum(w.counts) < 90 for *_, w in cases)  # some paths cut short
    monkeypatch.setattr(sim.observation_record, "_record_writer", None)
    assert compiled == answers()


# --- whole episodes, in a process each way ---------------------------------------------------

# The fast tier's: a junction, three egos on a curve, replayed traffic in a reactive bubble.
FAST_SCENARIOS = ["p000_left_turn_t_low", "p020_cruise_3lane_curve_low_3agents",
                  "p029_replay_i80_bubble"]  # fmt: skip


def episode_digests(scenario_ids: list[str], steps: int) -> dict[str, list[str]]:
    """For each scenario, the sha256 of every observation and of the record of three episodes of
    at most ``steps`` steps: the planner (dict observations), seeded random Continuous actions
    (the arrays format's records) and keep-lane actions (the smarts2022 format, with neighbours'
    lane positions and road waypoints)."""
    from arena.scenario import load_scenario
    from scenarios.experts import PlannerAgent, planner_interface
    from sim.interface import AgentInterface
    from sim.simulation import Simulation

    def planner():
        agent = PlannerAgent()
        agent.reset()
        return agent.act

    def random_actions():
        rng = np.random.default_rng(3)
        return lambda obs: {
            a: [0.2 + 0.6 * u[0], 0.0, 1.2 * u[1] - 0.6]
            for a in sorted(obs)
            for u in [rng.uniform(size=2).tolist()]
        }

    runs = [
        (planner_interface(), False, planner),
        (AgentInterface(action_space="Continuous", observation_radius=150.0), True, random_actions),
        (
            AgentInterface(
                action_space="LaneWithContinuousSpeed",
                observation_format="smarts2022",
                road_waypoints=True,
            ),
            False,
            lambda: lambda obs: {a: [9.0, 0] for a in obs},
        ),
    ]
    out = {}
    for scenario_id in scenario_ids:
        folder = SHIPPED_PUBLIC_DIR / scenario_id
        digests = []
        for interface, arrays, make_policy in runs:
            sim = Simulation(load_scenario(folder), folder, interface, arrays=arrays)
            digest = hashlib.sha256()
            try:
                obs, act = sim.reset(), make_policy()
                while not sim.done and sim.step_count < steps:
                    for a in sorted(obs):
                        digest.update(
                            bytes(obs[a].record)
                            if arrays
                            else json.dumps(obs[a], sort_keys=True, default=_array_bits).encode()
                        )
                    obs = sim.step(act(obs) if obs else {})
                record = Path(os.environ["DIGEST_DIR"]) / f"{scenario_id}.npz"
                sim.write_record(record)
            finally:
                sim.close()
            digests += [digest.hexdigest(), hashlib.sha256(record.read_bytes()).hexdigest()]
        out[scenario_id] = digests
    return out


def _array_bits(value) -> list:
    array = np.asarray(value)
    return [str(array.dtype), list(array.shape), hashlib.sha256(array.tobytes()).hexdigest()]


def both_ways(scenario_ids: list[str], steps: int, tmp_path: Path) -> list[dict]:
    """:func:`episode_digests` with the compiled core and with the reference, side by side."""
    code = (
        "import json, sys; from tests.sim.test_compiled_core import episode_digests; "
        f"print(json.dumps(episode_digests({scenario_ids!r}, {steps})))"
    )
    processes = []
    for pure in ("0", "1"):
        folder = tmp_path / f"pure{pure}"
        folder.mkdir()
        env = {**os.environ, PURE_PYTHON_VARIABLE: pure, "DIGEST_DIR": str(folder)}
        processes.append(
            subprocess.Popen(
                [sys.executable, "-c", code], cwd=REPO, env=env, stdout=subprocess.PIPE, text=True
            )
        )
    results = []
    for process in processes:
        out, _ = process.communicate(timeout=3000)
        assert process.returncode == 0
        results.append(json.loads(out.splitlines()[-1]))
    return results


# Two simulator processes: the integration tier's (every public scenario, below, and this short
# sample); the fast tier keeps the function-level comparisons above.
@pytest.mark.slow
def test_episodes_are_the_same_bytes_with_the_compiled_core(tmp_path):
    compiled, reference = both_ways(FAST_SCENARIOS, 40, tmp_path)
    assert compiled == reference


@pytest.mark.integration
def test_every_public_scenario_is_the_same_bytes_with_the_compiled_core(tmp_path):
    manifest = json.loads((SHIPPED_PUBLIC_DIR / "manifest.json").read_text())
    ids = [entry["id"] for entry in manifest["scenarios"]]
    assert len(ids) > 30
    compiled, reference = both_ways(ids, 300, tmp_path)
    assert compiled.keys() == reference.keys()
    differing = [sid for sid in ids if compiled[sid] != reference[sid]]
    assert not differing


def test_the_switch_runs_the_reference_when_asked():
    code = "from sim.compiled import core_status; import sim.road.lane as m; "
    code += "print(core_status(), m._lane_search)"
    env = {**os.environ, PURE_PYTHON_VARIABLE: "1"}
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=REPO, env=env, capture_output=True, text=True, check=True
    )
    assert out.stdout.split() == ["pure-python", f"({PURE_PYTHON_VARIABLE})", "None"]


def test_every_compiled_source_is_a_core_module():
    sources = (REPO / "sim").rglob("*.pyx")
    assert sorted(MODULES) == sorted(
        ".".join(p.relative_to(REPO).with_suffix("").parts) for p in sources
    )


def test_a_core_module_not_built_is_said_once_and_the_reference_runs():
    with pytest.warns(RuntimeWarning, match="not built"):
        assert compiled("sim._not_built") is None
    assert all(compiled(name) is not None for name in MODULES)
