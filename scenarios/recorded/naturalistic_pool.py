"""The naturalistic replays of a suite build: every ego choice of every scene in an organiser's
folder, handed out without reuse in a seeded order that alternates between scenes."""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from arena.scenario import Family, Scenario
from scenarios.generators import Spec
from scenarios.ids import derive_seed, scenario_id
from scenarios.recorded.naturalistic import (
    Ego,
    NaturalisticScene,
    ego_choices,
    load_scenes,
    scene_net,
    write_naturalistic,
)


@dataclass
class NaturalisticPool:
    scenes: list[NaturalisticScene]
    nets: dict[str, Path]
    queue: list[tuple[NaturalisticScene, Ego]]  # next ego choices to hand out, first first

    @classmethod
    def load(cls, folder: Path, suite: str, seed: int, cache_dir: Path) -> NaturalisticPool:
        scenes = load_scenes(folder)
        rng = np.random.default_rng(derive_seed(suite, seed, "naturalistic"))
        nets, per_scene = {}, []
        for scene in scenes:
            nets[scene.name] = scene_net(scene, cache_dir)
            egos = ego_choices(scene, nets[scene.name])
            per_scene.append([(scene, egos[i]) for i in rng.permutation(len(egos))])
        # Round robin over scenes, so a short suite still samples every scene.
        queue = [
            rows[k]
            for k in range(max(map(len, per_scene), default=0))
            for rows in per_scene
            if k < len(rows)
        ]
        return cls(scenes, nets, queue)

    def takes(self, spec: Spec) -> bool:
        """Whether this pool fills ``spec``: a one-agent non-reactive replay, while egos last."""
        return (
            spec.family is Family.replay
            and not spec.reactive
            and spec.agents == 1
            and bool(self.queue)
        )

    def write(self, out: Path, suite: str, index: int, seed: int) -> Scenario:
        scene, ego = self.queue.pop(0)
        sid = scenario_id(suite, index, Spec(Family.replay, f"ngsim_{ego.kind}", None, 1, False))
        return write_naturalistic(out / sid, sid, scene, ego, self.nets[scene.name], seed)

    def scene_list(self) -> list[dict]:
        """Which scene files the build read (name and sha256), for the manifest."""
        return [
            {
                "scene": s.name,
                "file": s.source_file.name,
                "sha256": hashlib.sha256(s.source_file.read_bytes()).hexdigest(),
            }
            for s in self.scenes
        ]
