"""Simulator throughput: raw libsumo stepping vs our full step, side by side in one run.

A 3-lane, 3 km straight road with 100 background vehicles, 1,000 steps of 0.1 s. The raw side
starts SUMO with the same network, traffic and options and only calls ``simulationStep``. Our side
runs :class:`sim.simulation.Simulation` with one ego driven by a simple gap-keeping policy
(TargetPose): ego moved into SUMO, neighbours read, events detected, observation built, record
row kept, and the ``.npz`` record written at the end. The policy's own time is not counted.
Our side runs twice: with observation dicts (the native and smarts2022 formats) and with the
arrays observation written in place (``Simulation(arrays=True)``: the arrays format and learn's
environments). Each side runs in its own process (libsumo: one simulation per process); best of
three each, the sides taking turns so that a changing load falls on all of them.

Two clocks, as in ``bench/env_throughput.py``: wall time, and the side's CPU time. On a shared,
loaded machine wall time mostly measures the neighbours, so ``ratio`` uses CPU time.

Both our sides run once more with the simulator's pure-Python reference instead of its compiled
core (``ARENA_PURE_PYTHON=1``, ``sim/compiled.py``), taking turns with the others.

Usage: ``python bench/sim_throughput.py [--steps 1000] [--vehicles 100] [--repeat 3]``.
The last line printed is ``ratio=<arrays_cpu/raw_cpu> native_ratio=<native_cpu/raw_cpu>
wall_ratio=<arrays_wall/raw_wall> pure_ratio=<pure arrays_cpu/raw_cpu>
compiled_speedup=<pure arrays_cpu/arrays_cpu>`` (target: ratio at most 2).

``--sumo-costs`` first prints what SUMO itself costs per step for the ways we could put an ego
into it and read its surroundings (libsumo only, no code of ours; an ego at constant speed along
the middle lane), each against raw stepping in the same run: see :data:`SUMO_VARIANTS`.
"""

from __future__ import annotations

import argparse
import cProfile
import io
import multiprocessing as mp
import os
import pstats
import tempfile
import time
from pathlib import Path
from queue import Empty

from _prerequisites import module, require, tool

from scenarios.handmade import (
    ScenarioSpec,
    lane_y,
    make_scenario,
    mission,
    straight_road,
    vehicle_xml,
)
from sim.compiled import PURE_PYTHON_VARIABLE, core_status

LANES = 3
ROAD_LENGTH = 3000.0  # [m]


def build(folder: Path, n_vehicles: int, steps: int) -> Path:
    vehicles = [
        vehicle_xml(f"bg{i}", 60.0 + (i // LANES) * 30.0, i % LANES, 15.0 + i % 7)
        for i in range(n_vehicles)
    ]
    spec = ScenarioSpec(
        missions=(
            mission(
                start=(20.0, lane_y(1, LANES), 0.0),
                goal=(ROAD_LENGTH - 5.0, lane_y(1, LANES)),
                speed=15.0,
            ),
        ),
        vehicles=vehicles,
        max_episode_steps=steps + 1,
        net=lambda f: straight_road(f, length=ROAD_LENGTH, lanes=LANES, speed=25.0),
    )
    return make_scenario(folder, spec)


def raw_side(folder: str, steps: int, queue) -> None:
    """``simulationStep`` only, in its own process: (wall, CPU) seconds."""
    # deferred: libsumo loads only in the process that simulates (one simulation per process)
    import libsumo

    # deferred: libsumo loads only in the process that simulates (one simulation per process)
    from arena.scenario import load_scenario
    from sim.traffic import sumo_command

    sc = load_scenario(Path(folder))
    libsumo.start(
        sumo_command(Path(folder) / sc.map, Path(folder) / sc.traffic.routes, sc.seed, 0.1)
    )
    wall, cpu = time.perf_counter(), time.process_time()
    for _ in range(steps):
        libsumo.simulationStep()
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    libsumo.close()
    queue.put(((wall, cpu), ""))


# name -> (moveToXY keepRoute mode or None for no ego, how many variables a context subscription
# of the ego reads (0: none), read it every step, subscribe every vehicle and read them all)
SUMO_VARIANTS: dict[str, tuple[int | None, int, bool, bool]] = {
    "raw": (None, 0, False, False),
    "ego keepRoute=2 (ours)": (2, 0, False, False),
    "ego keepRoute=1": (1, 0, False, False),
    "ego keepRoute=0": (0, 0, False, False),
    "ego + context 1 var": (2, 1, False, False),
    "ego + context 4 vars (ours)": (2, 4, False, False),
    "ego + context 1 var, read": (2, 1, True, False),
    "ego + context 4 vars, read (ours)": (2, 4, True, False),
    "ego + every vehicle 4 vars, read": (2, 0, False, True),
}


def sumo_side(folder: str, steps: int, variant: str, queue) -> None:
    """SUMO's own cost of one :data:`SUMO_VARIANTS` entry, in its own process: (wall, CPU) s."""
    # deferred: libsumo loads only in the process that simulates (one simulation per process)
    import libsumo

    # deferred: libsumo loads only in the process that simulates (one simulation per process)
    from arena.scenario import load_scenario
    from sim.traffic import sumo_command

    keep_route, n_vars, read_context, read_all = SUMO_VARIANTS[variant]
    tc = libsumo.constants
    variables = [tc.VAR_POSITION, tc.VAR_ANGLE, tc.VAR_SPEED, tc.VAR_LANE_ID]
    sc = load_scenario(Path(folder))
    libsumo.start(
        sumo_command(Path(folder) / sc.map, Path(folder) / sc.traffic.routes, sc.seed, 0.1)
    )
    x, y = sc.missions[0].start[:2]
    if keep_route is not None:
        libsumo.route.add("ego_route", list(sc.missions[0].route))
        libsumo.vehicle.add("ego", "ego_route", depart="now")
        libsumo.vehicle.setSpeedMode("ego", 0)
        libsumo.vehicle.setLaneChangeMode("ego", 0)
        libsumo.vehicle.moveToXY("ego", "", -1, x, y, 90.0, keepRoute=keep_route)
        if n_vars:
            libsumo.vehicle.subscribeContext(
                "ego", tc.CMD_GET_VEHICLE_VARIABLE, 110.0, variables[:n_vars]
            )
    libsumo.simulationStep()
    wall, cpu = time.perf_counter(), time.process_time()
    for _ in range(steps):
        if keep_route is not None:
            x += 1.5
            libsumo.vehicle.moveToXY("ego", "", -1, x, y, 90.0, keepRoute=keep_route)
            libsumo.vehicle.setPreviousSpeed("ego", 15.0)
        if read_all:
            for vid in libsumo.simulation.getDepartedIDList():
                libsumo.vehicle.subscribe(vid, variables)
        libsumo.simulationStep()
        if read_context:
            libsumo.vehicle.getContextSubscriptionResults("ego")
        if read_all:
            libsumo.vehicle.getAllSubscriptionResults()
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    libsumo.close()
    queue.put(((wall, cpu), ""))


def sumo_costs(folder: str, steps: int, repeat: int) -> None:
    best = dict.fromkeys(SUMO_VARIANTS, float("inf"))
    for _ in range(repeat):
        for variant in SUMO_VARIANTS:
            best[variant] = min(best[variant], in_child(sumo_side, folder, steps, variant)[0][1])
    for variant, cpu in best.items():
        print(
            f"SUMO {variant:34s} CPU {cpu * 1e3 / steps:.4f} ms/step"
            f"  ({cpu / best['raw']:.2f} x raw)"
        )


def follow_gap(obs: dict) -> list[float]:
    """Drive along the lane, slowing for the nearest vehicle ahead on it."""
    ego = obs["ego_vehicle_state"]
    x, y, _ = ego["position"]
    gap = min(
        (
            n["position"][0] - x
            for n in obs["neighborhood_vehicle_states"]
            if n["position"][0] > x and abs(n["position"][1] - y) < 1.6
        ),
        default=100.0,
    )
    return gap_action(x, y, gap)


def follow_gap_arrays(obs) -> list[float]:
    """:func:`follow_gap` on an arrays observation (its nearest neighbour slots)."""
    x, y, _ = obs.arrays["ego_vehicle_state"]["position"].tolist()
    nbr = obs.arrays["neighborhood_vehicle_states"]
    pos = nbr["position"][nbr["mask"].astype(bool)]
    ahead = pos[(pos[:, 0] > x) & (abs(pos[:, 1] - y) < 1.6), 0]
    return gap_action(x, y, float(ahead.min()) - x if len(ahead) else 100.0)


def gap_action(x: float, y: float, gap: float) -> list[float]:
    speed = min(25.0, max(0.0, (gap - 10.0) / 1.5))
    return [x + speed * 0.1, y, 0.0, 0.1]


def our_side(folder: str, steps: int, arrays: bool, profile: bool, queue) -> None:
    # deferred: libsumo loads only in the process that simulates (one simulation per process)
    from arena.scenario import load_scenario
    from sim.interface import AgentInterface
    from sim.simulation import Simulation

    sim = Simulation(load_scenario(Path(folder)), Path(folder), AgentInterface(), arrays=arrays)
    policy = follow_gap_arrays if arrays else follow_gap
    obs = sim.reset()
    profiler = cProfile.Profile() if profile else None
    policy_wall = policy_cpu = 0.0
    wall, cpu = time.perf_counter(), time.process_time()
    if profiler:
        profiler.enable()
    for _ in range(steps):
        t0, c0 = time.perf_counter(), time.process_time()
        actions = {a: policy(o) for a, o in obs.items()}
        policy_wall += time.perf_counter() - t0
        policy_cpu += time.process_time() - c0
        obs = sim.step(actions)
    sim.write_record(Path(folder).parent / "bench-record.npz")
    if profiler:
        profiler.disable()
    wall = time.perf_counter() - wall - policy_wall
    cpu = time.process_time() - cpu - policy_cpu
    assert sim.step_count == steps and sim.live, "the ego must drive the whole run"
    sim.close()
    text = ""
    if profiler:
        out = io.StringIO()
        pstats.Stats(profiler, stream=out).sort_stats("tottime").print_stats(25)
        text = out.getvalue()
    queue.put(((wall, cpu), text))


def in_child(target, *args, pure_python: bool = False) -> tuple[float, str]:
    """``target(*args, queue)`` in a process of its own; ``pure_python``: with the simulator's
    pure-Python reference (the switch is read as the child imports the simulator)."""
    ctx = mp.get_context("spawn")
    queue = ctx.Queue()
    proc = ctx.Process(target=target, args=(*args, queue))
    before = os.environ.get(PURE_PYTHON_VARIABLE)
    os.environ[PURE_PYTHON_VARIABLE] = "1" if pure_python else "0"
    try:
        proc.start()
    finally:
        if before is None:
            del os.environ[PURE_PYTHON_VARIABLE]
        else:
            os.environ[PURE_PYTHON_VARIABLE] = before
    try:
        result = queue.get(timeout=600)
    except Empty:
        raise SystemExit(f"{target.__name__} failed (exit code {proc.exitcode})") from None
    proc.join()
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=1000)
    parser.add_argument("--vehicles", type=int, default=100)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--profile", action="store_true", help="print where our side spends time")
    parser.add_argument(
        "--sumo-costs", action="store_true", help="first print SUMO's own cost of ego variants"
    )
    parser.add_argument("--smoke", action="store_true", help="20 steps, 5 vehicles, once")
    args = parser.parse_args()
    if args.smoke:
        args.steps, args.vehicles, args.repeat = 20, 5, 1
    require(
        tool("netconvert", "apt-get install sumo (or pip install eclipse-sumo)"),
        module("libsumo", "pip install libsumo (the project's dependencies)"),
    )
    with tempfile.TemporaryDirectory() as tmp:
        folder = str(build(Path(tmp) / "bench", args.vehicles, args.steps))
        if args.sumo_costs:
            sumo_costs(folder, args.steps, args.repeat)
        print(f"simulator core: {core_status()}")
        runs: dict[str, list[tuple[float, float]]] = {
            "raw": [],
            "native": [],
            "arrays": [],
            "native (pure Python)": [],
            "arrays (pure Python)": [],
        }
        for _ in range(args.repeat):
            runs["raw"].append(in_child(raw_side, folder, args.steps)[0])
            for pure in (False, True):
                suffix = " (pure Python)" if pure else ""
                for arrays in (False, True):
                    side = ("arrays" if arrays else "native") + suffix
                    result = in_child(our_side, folder, args.steps, arrays, False, pure_python=pure)
                    runs[side].append(result[0])
        if args.profile:
            for arrays in (False, True):
                print("arrays" if arrays else "native")
                print(in_child(our_side, folder, args.steps, arrays, True)[1])
    n = args.steps
    best = {name: (min(w for w, _ in side), min(c for _, c in side)) for name, side in runs.items()}
    for name, (wall, cpu) in best.items():
        print(
            f"{name + ':':22s} wall {n / wall:7,.0f} steps/s ({wall * 1e3 / n:.3f} ms/step)"
            f"   CPU {n / cpu:7,.0f} steps/s ({cpu * 1e3 / n:.3f} ms/step)"
            f"   {cpu / best['raw'][1]:.2f} x raw CPU"
        )
    raw_wall, raw_cpu = best["raw"]
    arrays_cpu, pure_cpu = best["arrays"][1], best["arrays (pure Python)"][1]
    print(
        f"ratio={arrays_cpu / raw_cpu:.2f} native_ratio={best['native'][1] / raw_cpu:.2f}"
        f" wall_ratio={best['arrays'][0] / raw_wall:.2f} pure_ratio={pure_cpu / raw_cpu:.2f}"
        f" compiled_speedup={pure_cpu / arrays_cpu:.2f}"
    )


if __name__ == "__main__":
    main()
