"""Benchmark: one ``act`` round trip per observation format, in-process vs process vs bubblewrap
vs Docker, side by side.

Target: the Docker median round trip with ``observation_format: arrays`` at most 1.3 times its
floor (the same round trip with an empty observation, below).

A trivial policy (one constant action per agent) gets a realistic observation per the agent
interface: one agent, 4 waypoint paths x 50 waypoints, 20 neighbours, a fresh one each round (the
sample scene driven on by a step: other objects and other values, made before the round's clock
starts), as a simulator sends them; re-sending one observation would time a cache. In-process
calls the policy object directly with the native observation; every other row is the full
evaluator path from the simulator's observation dict to the actions, once per format:

- ``native``: the observation dicts with their waypoint paths packed, as the simulator hands them
  to a sandboxed agent (``agent_runtime/packed_waypoints.py``; packed before the round's clock, as
  the simulator packs them in its step); pickle, frame, write; the runner unpickles, makes the
  waypoint dicts, calls the policy, answers in JSON; we decode the JSON.
- ``arrays``: the simulator writes each agent's observation into its fixed-shape record in place
  (``Simulation(arrays=True)``; here the round's record is written before the clock, by the
  encoder, into one record per agent reused every round, as the simulator's is); write the binary
  act frame of the records as they are; the runner copies each record and makes its numpy views,
  calls the policy, answers in JSON; we decode the JSON.

``docker (forked)`` is an agent forked in a warm Docker sandbox, as evaluations run them
(docs/protocol.md). Every sandbox row runs as an evaluation's first job does (``pin_jobs``,
``evaluator.sandbox.placement``): this process, the simulator's stand-in, and the sandbox both on
that job's CPU; its ``unpinned`` row is the same with both left to the scheduler, run beside it
(both sandboxes started, their round trips in turns of 100), so the last line shows what the
placement saves in one run. ``gvisor`` is the Docker sandbox under gVisor's runtime
(``ARENA_DOCKER_RUNTIME=runsc``, docs/sandbox.md "A stronger tier") where the daemon has it:
its agents run cold (a forked agent cannot make its episode's namespaces there), so its start,
a new sandbox per episode, is timed beside Docker's (``start s``: from launch to the policy
built, the median of the formats' starts, printed on the last line). The ``floor`` columns are
the same round trip with an empty observation (native: one agent with an empty dict; arrays: a
frame of no agents): what the transport alone costs, the rest of the median is encoding and
decoding the observation.

    python bench/sandbox_roundtrip.py [--steps 2000] [--kinds process,bubblewrap,docker,gvisor]

The last line is ``docker_median_ms=<arrays, Docker> docker_native_median_ms=<native, Docker>
bwrap_median_ms=<arrays, bubblewrap> docker_ratio=<arrays Docker / in-process>
docker_floor_ms=<arrays, Docker> gvisor_median_ms=<arrays, gVisor> docker_start_s=<Docker>
gvisor_start_s=<gVisor>``, all pinned, then ``docker_unpinned_ms=<arrays, Docker, unpinned>
docker_floor_unpinned_ms=<...> process_median_ms=<arrays, process> process_unpinned_ms=<...>
bwrap_unpinned_ms=<...>`` (nan where not measured).
"""

from __future__ import annotations

import argparse
import contextlib
import importlib.util
import tempfile
import time
from collections.abc import Callable
from itertools import chain, groupby
from operator import itemgetter
from pathlib import Path

import numpy as np

# The benchmark borrows the tests' settings helper: run from a checkout, the repository root.
from agent_runtime.packed_waypoints import POINT_VALUES
from arena.config import SandboxKind, SandboxSettings, Settings
from arena.settings_changes import with_fields
from evaluator.sandbox import start
from evaluator.sandbox.backend_registry import backend_for
from evaluator.sandbox.placement import job_cpus, pin_process
from evaluator.sandbox.warm import WarmAgent
from sim.interface import AgentInterface
from sim.observation_arrays import ObservationEncoder, ObservationLayout
from sim.observation_record import ArraysObservation
from submissions.intake import prepare_submission
from submissions.sample import sample_observation

TRIVIAL_POLICY = """
class Policy:
    def act(self, obs):
        return {agent_id: [10.0, 0.0] for agent_id in obs}
"""
FORMATS = ("native", "arrays")
GVISOR_ROW, GVISOR_RUNTIME = "gvisor", "runsc"
WARMUP = 200
BLOCK = 100  # rounds of one placement before the next one's turn (side_by_side)
EMPTY = {"native": {"Agent_0": {}}, "arrays": {}}
LANE_ID = itemgetter("lane_id")
UNPINNED = " unpinned"  # the suffix of a row's side-by-side run without placement


Observations = Callable[[int], dict]  # round -> the observation sent in that round


def timings_ms(act, observations: Observations, steps: int) -> np.ndarray:
    """``act`` round trips [ms], each with the round's observation (made before its clock)."""
    for i in range(WARMUP):
        act(observations(i))
    times = np.empty(steps)
    for i in range(steps):
        obs = observations(WARMUP + i)
        started = time.perf_counter()
        act(obs)
        times[i] = time.perf_counter() - started
    return times * 1000.0


def driving(step: int) -> dict[str, dict]:
    """The sample observation ``step`` steps (of 0.1 s at 12 m/s) down its road: new dicts and
    lists with other positions, headings and speeds every round."""
    obs = sample_observation()
    dx = 1.2 * step  # [m]
    for observation in obs.values():
        ego = observation["ego_vehicle_state"]
        ego["position"][0] += dx
        ego["speed"] += 0.01 * (step % 10)
        for n, other in enumerate(observation["neighborhood_vehicle_states"]):
            other["position"][0] += dx + 0.05 * step * (n % 3)  # some faster than the ego
            other["heading"] += 0.001 * (step % 7)
        for path in observation["waypoint_paths"]:
            for waypoint in path:
                waypoint["pos"][0] += dx
    return obs


def packed(observations: dict[str, dict]) -> dict[str, dict]:
    """``observations`` with their waypoint paths packed as the simulator packs them for a
    sandboxed agent (``sim.road.centrelines.packed``): a run of points per lane of each path,
    and x, y, heading and lane offset of every point in one float64 buffer."""
    for obs in observations.values():
        paths = obs["waypoint_paths"]
        runs = [
            (lane_id, w[0]["lane_index"], w[0]["lane_width"], w[0]["speed_limit"], len(w))
            for path in paths
            for lane_id, w in ((key, list(group)) for key, group in groupby(path, LANE_ID))
        ]
        values = [[w["pos"][0], w["pos"][1], w["heading"], w["lane_offset"]] for w in chain(*paths)]
        buffer = np.array(values, dtype=np.float64).reshape(-1, len(POINT_VALUES)).tobytes()
        obs["waypoint_paths"] = ([len(path) for path in paths], runs, buffer)
    return observations


def in_place(interface: AgentInterface) -> Observations:
    """``driving``'s observations as the simulator hands them to an arrays agent: each agent's
    record rewritten in place every round (:class:`sim.observation_record.ArraysObservation`)."""
    layout = ObservationLayout(interface)
    records: dict[str, tuple[ObservationEncoder, bytearray]] = {}

    def observations(step: int) -> dict[str, ArraysObservation]:
        out = {}
        for agent_id, observation in driving(step).items():
            encoder, record = records.setdefault(
                agent_id, (ObservationEncoder(layout), bytearray(layout.size))
            )
            encoder.write(observation, record)
            out[agent_id] = ArraysObservation(record, layout.arrays(record), False, None, "", "")
        return out

    return observations


def empty(fmt: str) -> Observations:
    """The same empty observation every round: the transport alone."""
    return lambda step: EMPTY[fmt]


def in_process_act(folder: Path):
    spec = importlib.util.spec_from_file_location("bench_policy", folder / "policy.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.Policy().act


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=2000)
    parser.add_argument("--kinds", default="process,bubblewrap,docker,gvisor")
    parser.add_argument("--smoke", action="store_true", help="20 steps, the process sandbox")
    args = parser.parse_args()
    if args.smoke:
        args.steps, args.kinds = 20, "process"

    base = Path(tempfile.mkdtemp(prefix="arena-bench-"))
    settings = with_fields(Settings(), storage={"data_dir": base / "data"})
    submissions = {}
    for name in FORMATS:
        source = base / f"src-{name}"
        source.mkdir()
        (source / "policy.py").write_text(TRIVIAL_POLICY)
        (source / "agent.yaml").write_text(f"observation_format: {name}\n")
        submissions[name] = prepare_submission(
            source,
            base / f"submission-{name}",
            settings.intake,
            settings.sandbox,
            settings.storage.resolved_data_dir,
        )

    # row -> format -> (times, floor times) [ms]
    results: dict[str, dict[str, tuple[np.ndarray, np.ndarray]]] = {}
    in_process = in_process_act(base / "src-native")
    results["in-process"] = {
        "native": (
            timings_ms(in_process, driving, args.steps),
            timings_ms(in_process, lambda step: {}, args.steps),
        )
    }
    labels = {"bench": "roundtrip"}
    starts: dict[str, list[float]] = {}  # row -> its sandboxes' start times [s]
    # An evaluation's first job's CPUs, whatever the setting: the pinned rows run there.
    pinned = job_cpus(0, settings.sandbox.model_copy(update={"pin_jobs": True}))
    data_dir = settings.storage.resolved_data_dir
    for name in args.kinds.split(","):
        kind, config = row_sandbox(name, settings)
        reason = backend_for(kind).unavailable_reason(config)
        if reason:
            print(f"{name}: skipped ({reason})")
            continue
        # Formats interleaved per row, and a row's placements in alternating blocks, so that
        # all see the same load on a shared machine.
        for fmt, submission in submissions.items():
            with contextlib.ExitStack() as stack:
                placed = {}
                for suffix, cpus in placements(pinned):
                    pin_process(cpus)  # an unpinned sandbox inherits nothing of the other's
                    started = time.perf_counter()
                    handle = stack.enter_context(
                        start(
                            submission,
                            kind=kind,
                            config=config,
                            data_dir=data_dir,
                            labels=labels,
                            cpus=cpus,
                        )
                    )
                    starts.setdefault(name + suffix, []).append(time.perf_counter() - started)
                    placed[suffix] = (cpus, handle.act)
                for suffix, timed in both(placed, submission, args.steps).items():
                    results.setdefault(name + suffix, {})[fmt] = timed
        if kind is SandboxKind.docker:
            for fmt, submission in submissions.items():
                with contextlib.ExitStack() as stack:
                    placed = {}
                    for suffix, cpus in placements(pinned):
                        pin_process(cpus)
                        warm = WarmAgent.start(
                            submission, kind, settings.sandbox, data_dir, labels=labels, cpus=cpus
                        )
                        stack.callback(warm.close)
                        forked = warm.fork(settings.sandbox, labels)
                        stack.callback(forked.close)
                        placed[suffix] = (cpus, stack.enter_context(forked.start()).act)
                    for suffix, timed in both(placed, submission, args.steps).items():
                        results.setdefault("docker (forked)" + suffix, {})[fmt] = timed
    pin_process(None)

    print(f"act round trip, {args.steps} steps, observation of 4 x 50 waypoints + 20 neighbours")
    columns = f"{'median ms':>10} {'p99 ms':>8} {'floor ms':>9}"
    print(f"{'':>24} {'native':^29} | {'arrays':^29} | {'arrays x in-process':>19}")
    print(f"{'':>24} {columns} | {columns} |")
    baseline = float(np.median(results["in-process"]["native"][0]))
    for name, row in results.items():
        cells = []
        for fmt in FORMATS:
            if fmt not in row:
                cells.append(f"{'-':>10} {'-':>8} {'-':>9}")
                continue
            times, floor = row[fmt]
            cells.append(
                f"{np.median(times):>10.4f} {np.percentile(times, 99):>8.4f} "
                f"{np.median(floor):>9.4f}"
            )
        ratio = median_of(results, name, "arrays", 0) / baseline
        print(f"{name:>24} {cells[0]} | {cells[1]} | {ratio:>19.1f}".replace("nan", "  -"))
    docker = median_of(results, "docker", "arrays", 0)
    print(
        f"docker_median_ms={docker:.4f} "
        f"docker_native_median_ms={median_of(results, 'docker', 'native', 0):.4f} "
        f"bwrap_median_ms={median_of(results, 'bubblewrap', 'arrays', 0):.4f} "
        f"docker_ratio={docker / baseline:.1f} "
        f"docker_floor_ms={median_of(results, 'docker', 'arrays', 1):.4f} "
        f"gvisor_median_ms={median_of(results, 'gvisor', 'arrays', 0):.4f} "
        f"docker_start_s={median_start(starts, 'docker'):.2f} "
        f"gvisor_start_s={median_start(starts, 'gvisor'):.2f} "
        f"docker_unpinned_ms={median_of(results, 'docker' + UNPINNED, 'arrays', 0):.4f} "
        f"docker_floor_unpinned_ms={median_of(results, 'docker' + UNPINNED, 'arrays', 1):.4f} "
        f"process_median_ms={median_of(results, 'process', 'arrays', 0):.4f} "
        f"process_unpinned_ms={median_of(results, 'process' + UNPINNED, 'arrays', 0):.4f} "
        f"bwrap_unpinned_ms={median_of(results, 'bubblewrap' + UNPINNED, 'arrays', 0):.4f}"
    )


def placements(pinned: tuple[int, ...] | None) -> list[tuple[str, tuple[int, ...] | None]]:
    """(row suffix, CPUs) of a row's runs: on the first job's CPUs, and unpinned; unpinned
    alone where there is one CPU."""
    if pinned is None:
        return [(UNPINNED, None)]
    return [("", pinned), (UNPINNED, None)]


def row_sandbox(name: str, settings: Settings) -> tuple[SandboxKind, SandboxSettings]:
    """A row's sandbox: a backend, or ``gvisor``, Docker under gVisor's runtime."""
    if name == GVISOR_ROW:
        return SandboxKind.docker, settings.sandbox.model_copy(
            update={"docker_runtime": GVISOR_RUNTIME}
        )
    return SandboxKind(name), settings.sandbox


def median_start(starts: dict[str, list[float]], name: str) -> float:
    return float(np.median(starts[name])) if name in starts else float("nan")


def floor_round_trip_ms(
    kind: SandboxKind, settings: Settings, fmt: str = "native", steps: int = 2000
) -> float:
    """The median ``act`` round trip [ms] of an empty observation to a trivial agent forked in a
    warm sandbox of ``kind``, as evaluations run agents (placed as their first job): what the
    transport alone costs per step (``bench/evaluate_suite.py`` adds it to raw SUMO stepping for
    its floor)."""
    base = Path(tempfile.mkdtemp(prefix="arena-bench-"))
    source = base / "src"
    source.mkdir()
    (source / "policy.py").write_text(TRIVIAL_POLICY)
    (source / "agent.yaml").write_text(f"observation_format: {fmt}\n")
    submission = prepare_submission(
        source,
        base / "submission",
        settings.intake,
        settings.sandbox,
        settings.storage.resolved_data_dir,
    )
    labels = {"bench": "floor"}
    # Placed as an evaluation's first job (pin_jobs): this process stands for its simulator.
    cpus = job_cpus(0, settings.sandbox)
    pin_process(cpus)
    warm = WarmAgent.start(
        submission,
        kind,
        settings.sandbox,
        settings.storage.resolved_data_dir,
        labels=labels,
        cpus=cpus,
    )
    forked = warm.fork(settings.sandbox, labels)
    try:
        with forked.start() as handle:
            return float(np.median(timings_ms(handle.act, empty(fmt), steps)))
    finally:
        forked.close()
        warm.close()
        pin_process(None)


def both(
    placed: dict[str, tuple[tuple[int, ...] | None, Callable]], submission, steps: int
) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """For each placement (row suffix -> its CPUs and its agent's act): round trips with fresh
    driving observations, as the simulator hands them to the submission's format, and with an
    empty observation [ms]."""
    fmt = submission.interface.observation_format
    fresh = in_place(submission.interface) if fmt == "arrays" else lambda i: packed(driving(i))
    timed = side_by_side(placed, fresh, steps)
    floors = side_by_side(placed, empty(fmt), steps)
    return {suffix: (timed[suffix], floors[suffix]) for suffix in placed}


def side_by_side(
    placed: dict[str, tuple[tuple[int, ...] | None, Callable]],
    observations: Observations,
    steps: int,
) -> dict[str, np.ndarray]:
    """``timings_ms`` of each placement's act, in turns of ``BLOCK`` rounds (this process, the
    simulator's stand-in, moved to the placement's CPUs for its turn): a load that comes and
    goes on a shared machine falls on all of them alike."""
    times: dict[str, list[float]] = {suffix: [] for suffix in placed}
    for cpus, act in placed.values():
        pin_process(cpus)
        for i in range(WARMUP):
            act(observations(i))
    for first in range(0, steps, BLOCK):
        for suffix, (cpus, act) in placed.items():
            pin_process(cpus)
            for i in range(first, min(first + BLOCK, steps)):
                obs = observations(WARMUP + i)
                started = time.perf_counter()
                act(obs)
                times[suffix].append(time.perf_counter() - started)
    return {suffix: np.array(values) * 1000.0 for suffix, values in times.items()}


def median_of(results: dict, name: str, fmt: str, column: int) -> float:
    """The median of ``column`` (0: the observation, 1: the floor) [ms]; NaN if not measured."""
    times = results.get(name, {}).get(fmt)
    return float(np.median(times[column])) if times is not None else float("nan")


if __name__ == "__main__":
    main()
