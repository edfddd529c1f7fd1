"""Benchmark: a native-format step's CPU on each side of the sandbox, with the waypoint paths sent
as dicts (what an in-process agent is given) and packed (what a sandboxed agent is sent,
``agent_runtime/packed_waypoints.py``), side by side in one run.

The reference planner drives each scenario of the public suite once (its actions kept); then each
side replays those actions, the two ways taking turns scenario by scenario, ``--repeat`` times:

- evaluator: ``Simulation.step`` plus pickling the step's act message, as the sandbox channel
  does (``evaluator/sandbox/channel.py``), CPU time per step;
- runtime: unpickling each act message and making its waypoint dicts (``Stream.receive`` in
  ``agent_runtime/main.py``), then a policy reading every waypoint's position, CPU time per
  message. The runtime makes a packed path's dicts when the policy reads them
  (``WaypointPath``); the same messages are also taken with every dict made up front (as before
  the lazy paths), each way read whole and read as the keep-lane example reads (the first
  waypoint of each path), taking turns.

    python bench/native_act.py [--repeat 3] [--max-steps 400]

The last line is ``evaluator_ratio=<packed/dicts> runtime_ratio=<packed/dicts>
evaluator_ms=<packed> runtime_ms=<packed> lazy_first_ratio=<lazy/eager, first waypoints read>
lazy_all_ratio=<lazy/eager, every waypoint read>``.
"""

from __future__ import annotations

import argparse
import io
import pickle
import time
from pathlib import Path

from agent_runtime.packed_waypoints import expand_observations, waypoint_paths
from arena.scenario import load_scenario
from arena.suite import SHIPPED_PUBLIC_DIR, load_suite
from evaluator.sandbox.channel import ObservationPickler
from scenarios.experts import PlannerAgent, planner_interface
from sim.simulation import Simulation


def episode(
    folder: Path, packed: bool, max_steps: int, actions: list[dict] | None = None
) -> tuple[float, list[bytes], list[dict]]:
    """(evaluator CPU [s], the act messages, the actions): the planner's actions when
    ``actions`` is None, else those replayed."""
    sim = Simulation(load_scenario(folder), folder, planner_interface(), packed_waypoints=packed)
    buffer = io.BytesIO()
    pickler = ObservationPickler(buffer, protocol=5)
    planner = PlannerAgent()
    messages, taken, cpu = [], [], 0.0
    try:
        obs = sim.reset()
        while obs and not sim.done and len(taken) < max_steps:
            action = planner.act(obs) if actions is None else actions[len(taken)]
            taken.append(action)
            started = time.process_time()
            buffer.seek(0)
            buffer.truncate()
            pickler.clear_memo()
            pickler.dump(("act", obs))
            obs = sim.step(action)
            cpu += time.process_time() - started
            messages.append(buffer.getvalue())
    finally:
        sim.close()
    return cpu, messages, taken


def eager(observations: dict) -> None:
    """Every waypoint dict made up front (the runtime before its lazy paths)."""
    for obs in observations.values():
        if isinstance(obs.get("waypoint_paths"), tuple):
            obs["waypoint_paths"] = waypoint_paths(*obs["waypoint_paths"])


def runtime_cpu(messages: list[bytes], expand=expand_observations, whole: bool = True) -> float:
    """CPU [s] to take ``messages`` as the runtime does (``expand``) and read every waypoint's
    position (``whole``) or the first waypoint's of each path."""
    started = time.process_time()
    for message in messages:
        _, body = pickle.loads(message)
        expand(body)
        for obs in body.values():
            for path in obs["waypoint_paths"]:
                if whole:
                    for waypoint in path:
                        waypoint["pos"]
                elif path:
                    path[0]["pos"]
        del body
    return time.process_time() - started


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--max-steps", type=int, default=400)
    parser.add_argument("--smoke", action="store_true", help="2 scenarios of 20 steps, once")
    args = parser.parse_args()
    if args.smoke:
        args.repeat, args.max_steps = 1, 20

    folders = [SHIPPED_PUBLIC_DIR / e.id for e in load_suite(SHIPPED_PUBLIC_DIR).scenarios]
    if args.smoke:
        folders = folders[:2]
    actions = {folder: episode(folder, False, args.max_steps)[2] for folder in folders}
    evaluator = dict.fromkeys((False, True), 0.0)
    runtime = dict.fromkeys((False, True), 0.0)
    lazy = dict.fromkeys(((expand_observations, True), (eager, True)), 0.0)
    lazy.update(dict.fromkeys(((expand_observations, False), (eager, False)), 0.0))
    steps = 0
    for rep in range(args.repeat):
        for folder in folders:
            for packed in (rep % 2 == 0, rep % 2 == 1):  # which goes first alternates
                cpu, messages, _ = episode(folder, packed, args.max_steps, actions[folder])
                evaluator[packed] += cpu
                runtime[packed] += runtime_cpu(messages)
                if packed:
                    for way in sorted(lazy, key=lambda w: (w[0] is eager) == (rep % 2 == 0)):
                        lazy[way] += runtime_cpu(messages, *way)
                steps += len(messages) if packed else 0
    print(f"{len(folders)} scenarios x {args.repeat}, {steps} steps a way, CPU ms per step:")
    for packed, name in ((False, "dicts"), (True, "packed")):
        print(
            f"  {name:>6}: evaluator {evaluator[packed] * 1e3 / steps:.4f}"
            f"  runtime {runtime[packed] * 1e3 / steps:.4f}"
        )
    for whole in (True, False):
        print(
            f"  packed, {'every waypoint' if whole else 'first waypoints'} read: runtime with"
            f" every dict made up front {lazy[eager, whole] * 1e3 / steps:.4f},"
            f" made when read {lazy[expand_observations, whole] * 1e3 / steps:.4f}"
        )
    print(
        f"evaluator_ratio={evaluator[True] / evaluator[False]:.3f} "
        f"runtime_ratio={runtime[True] / runtime[False]:.3f} "
        f"evaluator_ms={evaluator[True] * 1e3 / steps:.4f} "
        f"runtime_ms={runtime[True] * 1e3 / steps:.4f} "
        f"lazy_first_ratio={lazy[expand_observations, False] / lazy[eager, False]:.3f} "
        f"lazy_all_ratio={lazy[expand_observations, True] / lazy[eager, True]:.3f}"
    )


if __name__ == "__main__":
    main()
