"""Reactive scenario generators, one per family, each a pure function of (spec, rng).

A generator returns a :class:`Draft` (map template, missions, background traffic, triggers); the
suite builder turns it into a scenario folder. Registered in :data:`GENERATORS` by family.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from arena.scenario import Family, Goal, LaneChangeTrigger, Mission
from scenarios.maps import build_map
from scenarios.netinfo import NetInfo, net_info
from scenarios.traffic import (
    VOLUME_PER_LANE,
    Flow,
    Routes,
    Vehicle,
    clear_around,
    driver_types,
    initial_vehicles,
    slow_type,
)
from scenarios.variants import Variant, check_variant, variant_of

GOAL_BEFORE_END = 40.0  # [m] goals sit this far before the end of the route's final edge
INTERSECTION_VOLUME_SCALE = 0.4  # crossing flows of both directions add up: keep gaps usable


@dataclass(frozen=True)
class Spec:
    """What to generate: one row of a suite composition."""

    family: Family
    variant: str
    volume: str | None
    agents: int = 1
    reactive: bool = True

    def __post_init__(self) -> None:
        check_variant(self.family, self.variant)

    @property
    def shape(self) -> Variant:
        """The variant's row in the table (reactive families)."""
        return variant_of(self.family, self.variant)


@dataclass
class Draft:
    template: str
    missions: list[Mission]
    routes: Routes = field(default_factory=Routes)
    triggers: list[LaneChangeTrigger] = field(default_factory=list)


class MapLibrary:
    """Built maps of one suite build (netconvert once per template, cached on disk)."""

    def __init__(self, cache_dir: Path) -> None:
        self.cache_dir = Path(cache_dir)
        self._paths: dict[str, Path] = {}

    def path(self, template: str) -> Path:
        if template not in self._paths:
            self._paths[template] = build_map(template, self.cache_dir)
        return self._paths[template]

    def info(self, template: str) -> NetInfo:
        return net_info(self.path(template))


Generator = Callable[[Spec, np.random.Generator, MapLibrary], Draft]


def make_mission(
    info: NetInfo,
    index: int,
    start: tuple[str, int, float],
    route: tuple[str, ...],
    goal_lane: int,
    start_speed: float,
    start_step: int = 0,
    goal_s: float | None = None,
) -> Mission:
    """Mission of ``Agent_<index>`` starting at (edge, lane, offset [m]) on ``route``; the goal sits
    on ``goal_lane`` of the route's final edge."""
    edge, lane, s = start
    final = route[-1]
    gs = info.length(final) - GOAL_BEFORE_END if goal_s is None else goal_s
    gx, gy, _ = info.pose(final, goal_lane, gs)
    return Mission(
        agent_id=f"Agent_{index}",
        start=info.pose(edge, lane, s),
        start_speed=round(start_speed, 2),
        start_step=start_step,
        route=route,
        goal=Goal(position=(gx, gy)),
    )


def _volume(spec: Spec, scale: float = 1.0) -> float:
    return VOLUME_PER_LANE[spec.volume or "mid"] * scale


def _highway_traffic(
    draft: Draft,
    info: NetInfo,
    rng: np.random.Generator,
    per_lane: float,
    keep_clear: list[tuple[int | None, float, float]],
    flow_begin: float,
) -> None:
    routes = draft.routes
    routes.vtypes = driver_types(rng)
    lanes = info.lanes("in")
    through = routes.route(("in", "out"))
    speed = info.speed("in")
    routes.vehicles += initial_vehicles(
        rng, "init_in", through, lanes, (5.0, info.length("in") - 10.0), per_lane, speed, keep_clear
    )
    routes.vehicles += initial_vehicles(
        rng, "init_out", routes.route(("out",)), lanes, (5.0, 250.0), per_lane, speed, []
    )
    routes.flows.append(
        Flow("flow_in", through, per_lane * lanes * rng.uniform(0.85, 1.15), begin=flow_begin)
    )


def cruise(spec: Spec, rng: np.random.Generator, maps: MapLibrary) -> Draft:
    template = spec.shape.template
    info = maps.info(template)
    draft = Draft(template, [])
    lanes = rng.permutation(info.lanes("in"))[: spec.agents]
    delays = [0, *sorted(int(d) for d in rng.integers(5, 25, spec.agents - 1))]
    for i, (lane, delay) in enumerate(zip(lanes, delays, strict=True)):
        goal_lane = int(rng.integers(info.lanes("out")))
        draft.missions.append(
            make_mission(
                info,
                i,
                ("in", int(lane), 40.0),
                ("in", "out"),
                goal_lane,
                rng.uniform(8, 14),
                delay,
            )
        )
    # An agent entering later must not appear in front of traffic already closing in on its
    # start: every lane is kept free far enough behind that nothing arrives before it does.
    keep = [
        (None if delay else int(lane), 40.0, 70.0 if delay else 25.0)
        for lane, delay in zip(lanes, delays, strict=True)
    ]
    _highway_traffic(draft, info, rng, _volume(spec), keep, flow_begin=max(delays) * 0.1 + 3.0)
    return draft


def overtake(spec: Spec, rng: np.random.Generator, maps: MapLibrary) -> Draft:
    template = spec.shape.template
    info = maps.info(template)
    lane = 0
    draft = Draft(template, [])
    draft.missions.append(
        make_mission(info, 0, ("in", lane, 30.0), ("in", "out"), lane, rng.uniform(10, 14))
    )
    # Other lanes carry the volume's traffic; the ego lane ahead is blocked by slow leaders.
    _highway_traffic(draft, info, rng, _volume(spec, 0.6), [(lane, 30.0, 25.0)], flow_begin=3.0)
    slow_speed = rng.uniform(5.0, 7.0) if spec.shape.slow_leaders else rng.uniform(9.0, 12.0)
    draft.routes.special_types.append(slow_type("slow", slow_speed))
    through = draft.routes.route(("in", "out"))
    lead = 30.0 + rng.uniform(35.0, 55.0)
    draft.routes.vehicles = clear_around(draft.routes.vehicles, lane, lead, lead - 25.0, 80.0)
    draft.routes.vehicles.append(Vehicle("slow_0", through, 0.0, lane, lead, slow_speed, "slow"))
    if info.lanes("in") >= 3:
        second = lead + rng.uniform(30.0, 60.0)
        draft.routes.vehicles = clear_around(draft.routes.vehicles, 1, second)
        draft.routes.vehicles.append(Vehicle("slow_1", through, 0.0, 1, second, slow_speed, "slow"))
    return draft


def cut_in(spec: Spec, rng: np.random.Generator, maps: MapLibrary) -> Draft:
    template = spec.shape.template
    info = maps.info(template)
    lane, cutter_lane = 1, 2
    draft = Draft(template, [])
    draft.missions.append(
        make_mission(info, 0, ("in", lane, 30.0), ("in", "out"), lane, rng.uniform(12, 15))
    )
    keep: list[tuple[int | None, float, float]] = [(lane, 30.0, 25.0), (cutter_lane, 30.0, 25.0)]
    _highway_traffic(draft, info, rng, _volume(spec, 0.7), keep, flow_begin=3.0)
    through = draft.routes.route(("in", "out"))
    draft.routes.special_types.append(slow_type("cutter", rng.uniform(14.0, 17.0)))
    ahead = 30.0 + rng.uniform(20.0, 35.0)
    draft.routes.vehicles = clear_around(draft.routes.vehicles, cutter_lane, ahead)
    draft.routes.vehicles.append(Vehicle("cutin", through, 0.0, cutter_lane, ahead, 13.0, "cutter"))
    draft.triggers.append(
        LaneChangeTrigger(
            vehicle="cutin", agent_id="Agent_0", gap_m=round(rng.uniform(8.0, 14.0), 1)
        )
    )
    return draft


def merge(spec: Spec, rng: np.random.Generator, maps: MapLibrary) -> Draft:
    template = spec.shape.template
    info = maps.info(template)
    route = ("ramp", "merge", "out")
    draft = Draft(template, [])
    draft.missions.append(
        make_mission(
            info, 0, ("ramp", 0, 20.0), route, info.driving_lanes("out")[0], rng.uniform(8, 12)
        )
    )
    keep: list[tuple[int | None, float, float]] = []
    if spec.agents > 1:
        main = ("in", "merge", "out")
        delay = int(rng.integers(0, 30))
        goal_lane = int(rng.choice(info.driving_lanes("out")))
        draft.missions.append(
            make_mission(info, 1, ("in", 0, 60.0), main, goal_lane, rng.uniform(10, 14), delay)
        )
        keep.append((None if delay else 0, 60.0, 70.0 if delay else 25.0))
    routes = draft.routes
    routes.vtypes = driver_types(rng)
    lanes = info.lanes("in")
    main_route = routes.route(("in", "merge", "out"))
    per_lane = _volume(spec, 0.8)
    speed = info.speed("in")
    routes.vehicles += initial_vehicles(
        rng, "init_in", main_route, lanes, (5.0, info.length("in") - 10.0), per_lane, speed, keep
    )
    routes.flows.append(
        Flow("flow_in", main_route, per_lane * lanes * rng.uniform(0.85, 1.15), begin=4.0)
    )
    routes.flows.append(
        Flow("flow_ramp", routes.route(route), rng.uniform(60, 150), lane="0", begin=8.0)
    )
    return draft


def _intersection_traffic(
    draft: Draft, info: NetInfo, rng: np.random.Generator, per_lane: float, arms: list[str]
) -> None:
    """Flows from every incoming arm to every reachable outgoing arm; main-road arms (more
    lanes) carry ``per_lane`` per lane, minor arms a quarter of it; turns are a minority. Main
    arms start populated."""
    routes = draft.routes
    routes.vtypes = driver_types(rng)
    for src in arms:
        lanes = info.lanes(src)
        rate = per_lane * lanes * (1.0 if lanes > 1 else 0.25)
        for direction, share in (("s", 0.7), ("l", 0.15), ("r", 0.15)):
            dst = info.turn(src, direction)
            if dst is None:
                continue
            routes.flows.append(
                Flow(
                    f"flow_{src}_{direction}",
                    routes.route((src, dst)),
                    rate * share * rng.uniform(0.8, 1.2),
                    lane="best",
                )
            )
        straight = info.turn(src, "s")
        if lanes > 1 and straight is not None:
            # The main road carries traffic from step 0, not only after the first arrivals.
            routes.vehicles += initial_vehicles(
                rng,
                f"init_{src}",
                routes.route((src, straight)),
                lanes,
                (5.0, info.length(src) - 40.0),
                per_lane * 0.7,
                info.speed(src),
                [],
            )


def left_turn_t(spec: Spec, rng: np.random.Generator, maps: MapLibrary) -> Draft:
    return _turn(spec, rng, maps, ["w_in", "e_in", "s_in"])


def turn_c(spec: Spec, rng: np.random.Generator, maps: MapLibrary) -> Draft:
    return _turn(spec, rng, maps, ["w_in", "e_in", "s_in", "n_in"])


def _turn(spec: Spec, rng: np.random.Generator, maps: MapLibrary, arms: list[str]) -> Draft:
    template, direction, goal_lane = spec.shape.template, spec.shape.turn, spec.shape.goal_lane
    info = maps.info(template)
    target = info.turn("s_in", direction)
    assert target is not None, f"{template}: no {direction} turn from s_in"
    lane = int(rng.integers(info.lanes(target))) if goal_lane is None else goal_lane
    start = info.length("s_in") - rng.uniform(50.0, 70.0)
    draft = Draft(template, [])
    draft.missions.append(
        make_mission(
            info, 0, ("s_in", 0, start), ("s_in", target), lane, rng.uniform(5, 9), goal_s=80.0
        )
    )
    _intersection_traffic(draft, info, rng, _volume(spec, INTERSECTION_VOLUME_SCALE), arms)
    return draft


GENERATORS: dict[Family, Generator] = {
    Family.cruise: cruise,
    Family.overtake: overtake,
    Family.cut_in: cut_in,
    Family.merge: merge,
    Family.left_turn_t: left_turn_t,
    Family.turn_c: turn_c,
}
