"""Reactive background traffic: heterogeneous driver types, routes, flows and single vehicles,
written as a SUMO ``.rou.xml``.

Every number comes from the ``np.random.Generator`` handed in, so the file is a pure function of the
generator's seed; floats are written with fixed precision so the bytes are reproducible.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

# Flow per lane [veh/h] for each volume level.
VOLUME_PER_LANE = {"low": 250.0, "mid": 500.0, "high": 900.0}


@dataclass(frozen=True)
class Flow:
    id: str
    route: str
    per_hour: float  # [veh/h]
    lane: str = "random"  # SUMO departLane
    begin: float = 0.0  # [s]
    end: float = 100.0  # [s]
    type: str = "drivers"


@dataclass(frozen=True)
class Vehicle:
    id: str
    route: str
    depart: float  # [s]
    lane: int
    pos: float  # [m] departPos
    speed: float  # [m/s] departSpeed
    type: str = "drivers"


@dataclass
class Routes:
    """Everything one ``.rou.xml`` holds; ``to_xml`` sorts vehicles by departure as SUMO needs."""

    vtypes: list[dict[str, str]] = field(default_factory=list)  # the "drivers" distribution
    special_types: list[dict[str, str]] = field(default_factory=list)  # scripted vehicles' types
    routes: dict[str, tuple[str, ...]] = field(default_factory=dict)
    flows: list[Flow] = field(default_factory=list)
    vehicles: list[Vehicle] = field(default_factory=list)

    def route(self, edges: tuple[str, ...]) -> str:
        """Id of the route over ``edges``, added on first use."""
        rid = "r_" + "__".join(edges)
        self.routes.setdefault(rid, edges)
        return rid

    def to_xml(self) -> str:
        lines = ['<?xml version="1.0" encoding="UTF-8"?>', "<routes>"]
        for vt in self.vtypes + self.special_types:
            attrs = " ".join(f'{k}="{v}"' for k, v in vt.items())
            lines.append(f"  <vType {attrs}/>")
        if self.vtypes:
            ids = " ".join(vt["id"] for vt in self.vtypes)
            lines.append(f'  <vTypeDistribution id="drivers" vTypes="{ids}"/>')
        for rid, edges in self.routes.items():
            lines.append(f'  <route id="{rid}" edges="{" ".join(edges)}"/>')
        departures: list[tuple[float, str, str]] = []
        for v in self.vehicles:
            departures.append(
                (
                    v.depart,
                    v.id,
                    f'  <vehicle id="{v.id}" type="{v.type}" route="{v.route}" '
                    f'depart="{v.depart:.1f}" departLane="{v.lane}" departPos="{v.pos:.1f}" '
                    f'departSpeed="{v.speed:.2f}"/>',
                )
            )
        for f in self.flows:
            departures.append(
                (
                    f.begin,
                    f.id,
                    f'  <flow id="{f.id}" type="{f.type}" route="{f.route}" begin="{f.begin:.1f}" '
                    f'end="{f.end:.1f}" period="exp({f.per_hour / 3600.0:.5f})" '
                    f'departLane="{f.lane}" departSpeed="desired"/>',
                )
            )
        lines += [text for _, _, text in sorted(departures)]
        lines.append("</routes>")
        return "\n".join(lines) + "\n"


def driver_types(
    rng: np.random.Generator, n: int = 5, prefix: str = "driver", speed_scale: float = 1.0
) -> list[dict[str, str]]:
    """``n`` heterogeneous drivers: Krauss or IDM car following, imperfection, desired speed,
    headway and lane-change temperament drawn per type."""
    types = []
    for i in range(n):
        idm = bool(rng.random() < 0.5)
        vt = {
            "id": f"{prefix}{i}",
            "vClass": "passenger",
            "length": f"{rng.uniform(4.2, 5.2):.2f}",
            "width": f"{rng.uniform(1.7, 2.0):.2f}",
            "minGap": f"{rng.uniform(1.5, 3.0):.2f}",
            "accel": f"{rng.uniform(1.8, 3.2):.2f}",
            "decel": f"{rng.uniform(3.5, 5.0):.2f}",
            "emergencyDecel": "9.0",
            "tau": f"{rng.uniform(0.9, 1.6):.2f}",
            "carFollowModel": "IDM" if idm else "Krauss",
            "speedFactor": f"normc({speed_scale * rng.uniform(0.85, 1.1):.3f},0.08,0.5,1.2)",
            "lcStrategic": f"{rng.uniform(0.5, 2.0):.2f}",
            "lcSpeedGain": f"{rng.uniform(0.5, 2.5):.2f}",
            "lcCooperative": f"{rng.uniform(0.3, 1.0):.2f}",
            "lcAssertive": f"{rng.uniform(1.0, 3.0):.2f}",
            "lcKeepRight": f"{rng.uniform(0.5, 2.0):.2f}",
            "jmIgnoreFoeProb": "0",
            "probability": f"{rng.uniform(0.5, 1.5):.3f}",
        }
        if not idm:
            vt["sigma"] = f"{rng.uniform(0.2, 0.7):.2f}"
        types.append(vt)
    return types


def slow_type(type_id: str, max_speed: float) -> dict[str, str]:
    """A slow, calm driver that keeps its lane (overtaking scenarios' leaders)."""
    return {
        "id": type_id,
        "vClass": "passenger",
        "length": "4.8",
        "width": "1.9",
        "maxSpeed": f"{max_speed:.2f}",
        "speedFactor": "1.0",
        "accel": "1.5",
        "decel": "4.0",
        "sigma": "0.1",
        "lcStrategic": "1.0",
        "lcSpeedGain": "0",
        "lcKeepRight": "0",
    }


def initial_vehicles(
    rng: np.random.Generator,
    prefix: str,
    route: str,
    lanes: int,
    span: tuple[float, float],
    per_lane_hour: float,
    speed: float,
    keep_clear: list[tuple[int | None, float, float]],
) -> list[Vehicle]:
    """Vehicles already on the road at step 0 so traffic is established from the start.

    Gaps are exponential with the mean spacing of a flow of ``per_lane_hour`` at ``speed``;
    ``keep_clear`` lists (lane or None for every lane, position [m], distance behind [m]) spots
    (mission starts) left free from that distance behind to 25 m ahead."""
    mean_gap = max(speed * 3600.0 / per_lane_hour, 20.0)
    # SUMO inserts a vehicle only with a safe gap to the one ahead; one that cannot enter at step
    # 0 would pop in later wherever there is room, possibly beside a mission vehicle.
    min_gap = 1.6 * speed + 6.0
    out: list[Vehicle] = []
    for lane in range(lanes):
        pos = span[0] + rng.uniform(0.0, mean_gap)
        while pos < span[1]:
            if not any(
                (ln is None or ln == lane) and -behind < pos - p < 25.0
                for ln, p, behind in keep_clear
            ):
                out.append(
                    Vehicle(f"{prefix}{lane}_{len(out)}", route, 0.0, lane, pos, speed * 0.9)
                )
            pos += max(rng.exponential(mean_gap), min_gap)
    return out


def clear_around(
    vehicles: list[Vehicle], lane: int, pos: float, behind: float = 100.0, ahead: float = 30.0
) -> list[Vehicle]:
    """``vehicles`` without those departing on ``lane`` from ``behind`` [m] before ``pos`` to
    ``ahead`` [m] after it. SUMO refuses to insert a slow vehicle while a faster follower could not
    brake for it, and would insert it later, anywhere."""
    return [v for v in vehicles if v.lane != lane or not -behind < v.pos - pos < ahead]
