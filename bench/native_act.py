"""Benchmark: a native-format step's CPU on each side of the sandbox, with the waypoint paths sent
as dicts (what an in-process agent is given) and packed (what a sandboxed agent is sent,
``agent_runtime/packed_waypoints.py``), side by side in one run.

The reference planner drives each scenario of the public suite once (its actions kept); then each
side replays those actions, the two ways taking turns scenario by scenario, ``--repeat`` times:

- evaluator: ``Simulation.step`` plus pickling the step's act message, as the sandbox channel
  does (``evaluator/sandbox/channel.py``), CPU time per step;
- runtime: unpickling each act message and making its waypoint dicts (``Stream.receive`` in
  ``agent_runtime/main.py``), then dropping it, CPU time per message.

    python bench/native_act.py [--repeat 3] [--max-steps 400]

The last line is ``evaluator_ratio=<packed/dicts> runtime_ratio=<packed/dicts>
evaluator_ms=<packed> runtime_ms=<packed>``.
"""

from __future__ import annotations

import argparse
import io
import pickle
import time
from pathlib import Path

from agent_runtime.packed_waypoints import expand_observations
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


def runtime_cpu(messages: list[bytes]) -> float:
    """CPU [s] to take ``messages`` as the runtime does."""
    started = time.process_time()
    for message in messages:
        _, body = pickle.loads(message)
        expand_observations(body)
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
    steps = 0
    for rep in range(args.repeat):
        for folder in folders:
            for packed in (rep % 2 == 0, rep % 2 == 1):  # which goes first alternates
                cpu, messages, _ = episode(folder, packed, args.max_steps, actions[folder])
                evaluator[packed] += cpu
                runtime[packed] += runtime_cpu(messages)
                steps += len(messages) if packed else 0
    print(f"{len(folders)} scenarios x {args.repeat}, {steps} steps a way, CPU ms per step:")
    for packed, name in ((False, "dicts"), (True, "packed")):
        print(
            f"  {name:>6}: evaluator {evaluator[packed] * 1e3 / steps:.4f}"
            f"  runtime {runtime[packed] * 1e3 / steps:.4f}"
        )
    print(
        f"evaluator_ratio={evaluator[True] / evaluator[False]:.3f} "
        f"runtime_ratio={runtime[True] / runtime[False]:.3f} "
        f"evaluator_ms={evaluator[True] * 1e3 / steps:.4f} "
        f"runtime_ms={runtime[True] * 1e3 / steps:.4f}"
    )


if __name__ == "__main__":
    main()
