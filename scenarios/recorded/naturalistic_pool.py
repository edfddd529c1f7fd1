"""The corpus replays of a suite build: the one-agent non-reactive replay rows of each kind
(cruise, lane change, turns) are filled from the ego choices of that kind of every usable scene of
an organiser's folder, drawn by the suite seed; a recorded vehicle is the mission of at most one
scenario, whichever scene files it appears in. A drawn mission enters the suite only once the log
replay expert has finished it; one it does not finish is listed with the reason and the next is
drawn. Rows no candidate fits keep our SUMO replays."""

from __future__ import annotations

import shutil
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from arena.scenario import DataLabel, Family, Scenario
from scenarios.generators import Spec
from scenarios.ids import derive_seed, scenario_id
from scenarios.recorded.corpus import Corpus, CorpusScene, TrackKey, read_corpus
from scenarios.recorded.naturalistic import Ego, NaturalisticImportError, write_naturalistic
from scenarios.verify import replay_unsolved

TRACKS_FILE = "naturalistic-tracks.json"  # in a built suite's folder, beside manifest.json


@dataclass
class NaturalisticPool:
    corpus: Corpus
    rng: np.random.Generator
    by_kind: dict[str, list[tuple[CorpusScene, Ego]]]  # candidates in file and vehicle order
    cache_dir: Path  # maps, and the expert's verdicts
    used_vehicles: set[TrackKey] = field(default_factory=set)  # identities already missions
    used_scenes: dict[str, CorpusScene] = field(default_factory=dict)  # by file name
    unsolved: list[dict] = field(default_factory=list)  # drawn, not finished by the expert

    @classmethod
    def load(
        cls,
        folder: Path,
        suite: str,
        seed: int,
        cache_dir: Path,
        *,
        label: DataLabel | None = None,
        licence: Path | None = None,
        jobs: int = 1,
        progress: Callable[[str], None] = lambda _: None,
    ) -> NaturalisticPool:
        """Read ``folder``; fails only when no scene of it gives a single usable mission."""
        corpus = read_corpus(
            folder, cache_dir, label=label, licence=licence, jobs=jobs, progress=progress
        )
        if corpus.candidates() == 0:
            why = "; ".join(f"{s.file}: {s.reason}" for s in corpus.skipped[:10])
            raise NaturalisticImportError(
                f"{folder}: no usable mission in {len(corpus.scenes)} usable of "
                f"{len(corpus.scenes) + len(corpus.skipped)} scene files "
                f"(rejected vehicles: {corpus.rejected() or 'none'}; skipped: {why or 'none'})"
            )
        by_kind: dict[str, list[tuple[CorpusScene, Ego]]] = {}
        for s in corpus.scenes:
            for ego in s.egos:
                by_kind.setdefault(ego.kind, []).append((s, ego))
        rng = np.random.default_rng(derive_seed(suite, seed, "naturalistic"))
        return cls(corpus, rng, by_kind, cache_dir)

    def _free(self, kind: str) -> list[tuple[CorpusScene, Ego]]:
        return [
            (s, ego)
            for s, ego in self.by_kind.get(kind, ())
            if self.corpus.identity[(s.file, ego.vehicle_id)] not in self.used_vehicles
        ]

    def takes(self, spec: Spec) -> bool:
        """Whether this pool fills ``spec``: a one-agent non-reactive replay of a kind it has an
        unused vehicle of."""
        return (
            spec.family is Family.replay
            and not spec.reactive
            and spec.agents == 1
            and bool(self._free(spec.variant))
        )

    def write(
        self, out: Path, suite: str, index: int, spec: Spec, seed: int
    ) -> tuple[Scenario, str] | None:
        """Row ``index`` (``spec``) from a candidate of its kind drawn by the seed that the log
        replay expert finishes: the scenario and its provenance source; None when no candidate
        of the kind is left."""
        while free := self._free(spec.variant):
            s, ego = free[int(self.rng.integers(len(free)))]
            self.used_vehicles.add(self.corpus.identity[(s.file, ego.vehicle_id)])
            variant = f"{s.scene.variant_prefix}_{ego.kind}"
            sid = scenario_id(suite, index, Spec(Family.replay, variant, None, 1, False))
            scenario = write_naturalistic(out / sid, sid, s.scene, ego, s.net, seed)
            reason = replay_unsolved(out / sid, self.cache_dir)
            if reason is None:
                self.used_scenes[s.file] = s
                return scenario, s.scene.provenance.source
            shutil.rmtree(out / sid)
            self.unsolved.append({"file": s.file, "vehicle": ego.vehicle_id, "reason": reason})
        return None

    def scene_list(self) -> list[dict]:
        """The scene files the suite's scenarios were cut from, by content and name (for the
        manifest), each with the origin of its local frame in the file's coordinates."""
        return [
            {
                "scene": s.scene.name,
                "file": s.file,
                "sha256": s.sha256(),
                "location": s.location,
                "source": s.scene.provenance.source,
                "origin": list(s.scene.origin),
            }
            for s in self._used()
        ]

    def track_list(self) -> dict[str, list[dict]]:
        """Every recorded vehicle's moving poses per scene file of :meth:`scene_list`: what a
        dataset build must not contain (``--exclude-suite``), beside the manifest (:data:
        `TRACKS_FILE`) so the manifest every evaluation reads stays small."""
        return {
            s.file: [
                {"vehicle": vehicle, "poses": [list(p) for p in poses]}
                for vehicle, poses in s.tracks().items()
            ]
            for s in self._used()
        }

    def _used(self) -> list[CorpusScene]:
        return [self.used_scenes[file] for file in sorted(self.used_scenes)]

    def skipped_list(self) -> list[dict]:
        return [{"file": s.file, "reason": s.reason} for s in self.corpus.skipped]
