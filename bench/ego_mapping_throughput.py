"""SUMO's mapping of the egos: the search near them against the simulator's mapping, side by side.

The simulator moves every ego into SUMO each step (``moveToXY``) so that SUMO's drivers see it.
SUMO's search near (keepRoute=2) scores every lane within 100 m of it, which is dear on the
junction maps; the simulator maps along the route where that gives the same lane
(:func:`sim.traffic.sumo_mapping`). For every SUMO-traffic scenario of a suite, each mission's
ego is moved along its route, lane by lane through the junctions, 1.5 m a step (a lane-keeping
ego at 15 m/s), with the scenario's traffic running: once told nothing (the search near alone,
as before) and once told our map's lane, as the simulator does. Only the moves are timed, in
CPU time (the machine is shared); each side runs in its own process (libsumo: one simulation per
process), best of ``--repeat``, the sides taking turns. Both sides must put every ego on the
same lane at the same position every step, or the run fails.

Usage: ``python bench/ego_mapping_throughput.py [--suite DIR] [--repeat 3]`` (default: the
shipped public suite; ``arena scenarios build --suite hidden --dev --out DIR`` makes the hidden
one). The last line printed is ``move_ratio=<ours/search CPU> search_us=<CPU µs a move>
ours_us=<...> along_route=<share of the moves mapped along the route>``.
"""

from __future__ import annotations

import argparse
import hashlib
import multiprocessing as mp
import time
from pathlib import Path

from _prerequisites import module, require

SPACING = 1.5  # [m] an ego's advance per step


def side(suite: str, tell_lane: bool, limit: int, queue) -> None:
    """Move the egos of the suite's SUMO-traffic scenarios; put (CPU s of the moves, moves,
    moves mapped along the route, digest of where SUMO put the egos) on ``queue``."""
    # deferred: libsumo loads only in the process that simulates (one simulation per process)
    from arena.scenario import load_scenario
    from sim.road import RoadNetwork
    from sim.road.waypoints import preferred_successor
    from sim.traffic import ALONG_ROUTE, SumoTraffic, sumo_mapping

    cpu, moves, along = 0.0, 0, 0
    where = hashlib.sha256()
    folders = [f for f in sorted(Path(suite).iterdir()) if (f / "scenario.json").is_file()]
    scenarios = [(f, load_scenario(f)) for f in folders]
    scenarios = [(f, sc) for f, sc in scenarios if sc.traffic.kind == "sumo"][:limit]
    for folder, sc in scenarios:
        road = RoadNetwork.load(folder / sc.map)
        paths = []  # per mission: (x, y, heading, our map's lane) every SPACING
        for m in sc.missions:
            x, y, heading = m.start
            lane, path = road.nearest_lane(x, y, heading).lane, []
            while lane is not None:
                for s in [k * SPACING for k in range(int(lane.length / SPACING))]:
                    px, py = lane.point_at(s)
                    h = float(lane.heading_at(s))
                    path.append((px, py, h, road.nearest_lane(px, py, h)))
                if lane.edge_id == m.route[-1]:
                    break
                lane = preferred_successor(road, lane, m.route)
            paths.append(path)
        traffic = SumoTraffic(folder / sc.map, folder / sc.traffic.routes, sc.seed, sc.step_length)
        vehicle = traffic.libsumo.vehicle
        try:
            for m in sc.missions:
                traffic.add_vehicle(m.agent_id, list(m.route), m.vehicle.length, m.vehicle.width)
            for k in range(max(map(len, paths))):
                now = [(m, p[k]) for m, p in zip(sc.missions, paths, strict=True) if k < len(p)]
                started = time.process_time()
                for m, (x, y, h, lane) in now:
                    traffic.move(m.agent_id, x, y, h, 15.0, lane if tell_lane else None)
                cpu += time.process_time() - started
                moves += len(now)
                along += sum(
                    sumo_mapping(lane, h, m.vehicle.length / 2, m.route) == ALONG_ROUTE
                    for m, (_, _, h, lane) in now
                )
                traffic.step()
                for m, _ in now:
                    seen = (vehicle.getLaneID(m.agent_id), vehicle.getLanePosition(m.agent_id))
                    where.update(repr(seen).encode())
        finally:
            traffic.close()
    queue.put((cpu, moves, along, where.hexdigest()))


def in_child(*args) -> tuple[float, int, int, str]:
    ctx = mp.get_context("spawn")
    queue = ctx.Queue()
    child = ctx.Process(target=side, args=(*args, queue))
    child.start()
    result = queue.get(timeout=3600)
    child.join()
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--suite", type=Path, help="a built suite (default: the public one)")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--smoke", action="store_true", help="2 scenarios, once")
    args = parser.parse_args()
    require(module("libsumo", "pip install libsumo (the project's dependencies)"))
    if args.suite is None:
        from arena.suite import SHIPPED_PUBLIC_DIR

        args.suite = SHIPPED_PUBLIC_DIR
    limit = 2 if args.smoke else 10**6
    if args.smoke:
        args.repeat = 1
    best: dict[bool, float] = {False: float("inf"), True: float("inf")}
    where: dict[bool, str] = {}
    for _ in range(args.repeat):
        for tell_lane in (False, True):
            cpu, moves, along, where[tell_lane] = in_child(str(args.suite), tell_lane, limit)
            best[tell_lane] = min(best[tell_lane], cpu)
    if where[False] != where[True]:
        raise SystemExit("the two mappings put an ego in different places: see sim.traffic")
    search, ours = (best[side] * 1e6 / max(1, moves) for side in (False, True))
    print(f"{moves} moves of the egos of {args.suite.name}: SUMO put each where the search did")
    print(
        f"move_ratio={ours / search:.2f} search_us={search:.1f} ours_us={ours:.1f}"
        f" along_route={along / max(1, moves):.2f}"
    )


if __name__ == "__main__":
    main()
