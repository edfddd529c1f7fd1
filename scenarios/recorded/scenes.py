"""The recorded scenes replays are cut from: a map and its heterogeneous traffic.

Each scene is recorded once per suite build (seeded from the suite seed) and cached on disk by the
hash of its inputs, since a recording is a pure function of map, routes and SUMO seed.
"""

from __future__ import annotations

import hashlib
import pickle
from dataclasses import dataclass

import numpy as np

from arena.files import write_atomically
from scenarios.generators import MapLibrary
from scenarios.recorded.builder import FLOWS_STOP_BEFORE_END_S
from scenarios.recorded.recorder import Recording, record_scene
from scenarios.traffic import Flow, Routes, driver_types


@dataclass(frozen=True)
class Scene:
    name: str
    template: str
    duration_s: float


SCENES = {
    "highway": Scene("highway", "replay_highway", 300.0),
    "cross": Scene("cross", "cross", 300.0),
    "urban": Scene("urban", "urban", 300.0),
}


def scene_routes(scene: Scene, rng: np.random.Generator, maps: MapLibrary) -> Routes:
    info = maps.info(scene.template)
    routes = Routes()
    routes.vtypes = driver_types(rng, 8)
    end = scene.duration_s - FLOWS_STOP_BEFORE_END_S
    if scene.name == "highway":
        routes.flows.append(
            Flow("main", routes.route(("in", "merge", "out")), rng.uniform(2600, 3200), end=end)
        )
        routes.flows.append(
            Flow(
                "ramp", routes.route(("ramp", "merge", "out")), rng.uniform(550, 700), "0", end=end
            )
        )
        return routes
    for src in sorted(e.getID() for e in info.net.getEdges() if _is_entry(e)):
        for direction in ("s", "l", "r"):
            dst = info.turn(src, direction)
            if dst is None:
                continue
            path = [src, dst]
            # On the urban avenue continue through the next junction so trips span two of them.
            nxt = info.turn(dst, "s") if scene.name == "urban" else None
            if nxt is not None:
                path.append(nxt)
            rate = (120.0 if info.lanes(src) > 1 else 60.0) * rng.uniform(0.8, 1.2)
            rate *= 2.0 if direction == "s" else 1.0
            routes.flows.append(
                Flow(f"{src}_{direction}", routes.route(tuple(path)), rate, "best", end=end)
            )
    return routes


def _is_entry(edge) -> bool:
    return not edge.getFromNode().getIncoming() or all(
        e.getFromNode() == edge.getToNode() for e in edge.getFromNode().getIncoming()
    )


def recorded(scene: Scene, seed: int, maps: MapLibrary) -> Recording:
    rng = np.random.default_rng(seed)
    routes = scene_routes(scene, rng, maps)
    net = maps.path(scene.template)
    key = hashlib.sha256(
        f"{net.name}\0{routes.to_xml()}\0{seed}\0{scene.duration_s}".encode()
    ).hexdigest()[:20]
    cache = maps.cache_dir / "recordings" / f"{scene.name}-{key}.pkl"
    if cache.exists():
        return pickle.loads(cache.read_bytes())
    recording = record_scene(net, routes, seed % 2**31, scene.duration_s)
    write_atomically(cache, pickle.dumps(recording))
    return recording
