"""An organiser's folder of recorded scenes, read for a suite or dataset build: every usable scene
with its map and its screened ego choices, every unusable file with its reason, and which
recorded vehicles of different scenes are one vehicle (:mod:`scenarios.recorded.tracks`).

A file that cannot be read, has no trajectory or whose map cannot be built is skipped, never
fatal: the build decides whether enough remains. Scenes are read in parallel with ``jobs``.
"""

from __future__ import annotations

import hashlib
from collections import Counter
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

from arena.errors import ArenaError
from arena.scenario import DataLabel
from scenarios.recorded.naturalistic import (
    Ego,
    NaturalisticImportError,
    NaturalisticScene,
    Skipped,
    load_scene,
    scene_files,
    scene_net,
    screen_egos,
)
from scenarios.recorded.tracks import Pose, TrackIndex, recording_location, track_poses

TrackKey = tuple[str, str]  # (scene file name, vehicle id)


@dataclass(frozen=True)
class CorpusScene:
    scene: NaturalisticScene
    net: Path
    egos: tuple[Ego, ...]
    rejected: dict[str, int]  # recorded vehicles that make no mission, per reason

    @property
    def file(self) -> str:
        """The scene's file name: what names a scene of a corpus (a file's own id need not be
        unique: two files may carry one ``benchmarkID``)."""
        return self.scene.source_file.name

    @property
    def location(self) -> str:
        return recording_location(self.scene.name)

    def tracks(self) -> dict[str, list[Pose]]:
        """Moving poses of every recorded vehicle, by vehicle id."""
        return {t.vehicle_id: track_poses(t) for t in self.scene.trajectories}

    def sha256(self) -> str:
        return hashlib.sha256(self.scene.source_file.read_bytes()).hexdigest()


@dataclass
class Corpus:
    scenes: list[CorpusScene]  # usable, in file-name order
    skipped: list[Skipped]
    # Every recorded vehicle's identity: the first (file, vehicle) it was seen as.
    identity: dict[TrackKey, TrackKey] = field(default_factory=dict)

    def rejected(self) -> dict[str, int]:
        total: Counter = Counter()
        for s in self.scenes:
            total.update(s.rejected)
        return dict(sorted(total.items()))

    def candidates(self) -> int:
        return sum(len(s.egos) for s in self.scenes)


def _read_one(path: Path, cache_dir: Path, label, licence) -> CorpusScene | Skipped:
    try:
        scene = load_scene(path, label, licence)
        net = scene_net(scene, cache_dir)
        egos, rejected = screen_egos(scene, net)
    except NaturalisticImportError as exc:
        return Skipped(path.name, str(exc).removeprefix(f"{path}: "))
    except (ArenaError, OSError, ValueError, RuntimeError) as exc:
        # netconvert refusing a map, a lanelet graph sumolib cannot read: the file's problem.
        return Skipped(path.name, f"its road cannot be built: {type(exc).__name__}: {exc}")
    return CorpusScene(scene, net, tuple(egos), dict(rejected))


def read_corpus(
    folder: Path,
    cache_dir: Path,
    *,
    label: DataLabel | None = None,
    licence: Path | None = None,
    jobs: int = 1,
    progress: Callable[[str], None] = lambda _: None,
) -> Corpus:
    """Read every scene file of ``folder`` (``progress`` is told each file name when done)."""
    files = scene_files(folder)
    results: list[CorpusScene | Skipped] = []
    if jobs > 1:
        with ProcessPoolExecutor(max_workers=jobs) as pool:
            futures = [pool.submit(_read_one, p, cache_dir, label, licence) for p in files]
            for path, future in zip(files, futures, strict=True):
                results.append(future.result())
                progress(path.name)
    else:
        for path in files:
            results.append(_read_one(path, cache_dir, label, licence))
            progress(path.name)
    corpus = Corpus(
        [r for r in results if isinstance(r, CorpusScene)],
        [r for r in results if isinstance(r, Skipped)],
    )
    corpus.identity = _identities(corpus.scenes)
    return corpus


def _identities(scenes: list[CorpusScene]) -> dict[TrackKey, TrackKey]:
    """One key per recorded vehicle: a vehicle seen in several scenes (of one recording, or a
    copy of a file under another name) gets one key, the smallest of its sightings. Sightings
    link transitively: a long scene can tie together two that do not overlap."""
    index = TrackIndex()
    parent: dict[TrackKey, TrackKey] = {}
    files: dict[TrackKey, set[str]] = {}  # per root: the files its sightings are in

    def root(key: TrackKey) -> TrackKey:
        while parent[key] != key:
            parent[key] = parent[parent[key]]
            key = parent[key]
        return key

    for s in scenes:
        tracks = s.tracks()
        same = index.same_vehicles(tracks)
        for vehicle in tracks:
            key = (s.file, vehicle)
            parent[key], files[key] = key, {s.file}
            for other in sorted(same.get(vehicle, ())):
                a, b = sorted((root(key), root(other)))
                # Two obstacles of one file are two vehicles, however alike (simulated traffic
                # drives identical paths at identical speeds): never join them, not even
                # through a third scene.
                if a != b and not files[a] & files[b]:
                    parent[b] = a
                    files[a] |= files.pop(b)
        index.add(s.file, tracks)
    return {key: root(key) for key in parent}
