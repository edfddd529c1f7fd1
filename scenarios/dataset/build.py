"""`arena dataset build`: recorded and naturalistic replays -> a Minari offline-RL dataset.

Sources: the corpus scenes (one episode per recorded vehicle that finishes its mission, once
per vehicle however many scene files it appears in, see :mod:`scenarios.recorded.corpus`) and the
non-reactive replays of the public set (our SUMO recordings). A scene sharing a file or a single
recorded vehicle with a hidden suite (its manifest's ``naturalistic_scenes``) is left out. Only
what the log replay expert finished is kept: a mission it does not finish is listed with the
reason. ``DIR/dataset-manifest.json`` says which scene files (by sha256 and name) and vehicles
it holds, which it left out and skipped, and why; a build that keeps no episode fails.
"""

from __future__ import annotations

import json
import os
import tempfile
import warnings
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from arena.errors import ArenaError
from arena.scenario import DataLabel, load_scenario
from scenarios.dataset.collect import Episode, collect
from scenarios.dataset.features import ACTION_SIZE, OBS_SIZE
from scenarios.recorded.corpus import Corpus, CorpusScene, read_corpus
from scenarios.recorded.naturalistic import write_naturalistic
from scenarios.recorded.naturalistic_pool import TRACKS_FILE
from scenarios.recorded.tracks import TrackIndex

DATASET_ID = "driving-arena/replays-v0"
MANIFEST = "dataset-manifest.json"
# The same transitions as plain numpy arrays: what a Track 2 train.py reads in the sandbox, which
# has numpy but neither minari nor h5py.
TRANSITIONS = "transitions.npz"


class DatasetError(ArenaError, ValueError):
    """A dataset build that would write nothing useful; the message says why."""


@dataclass(frozen=True)
class HiddenTracks:
    """What a built suite used of a corpus: scene files by sha256 (its manifest's
    ``naturalistic_scenes``) and every recorded vehicle's poses (its ``TRACKS_FILE``), matched
    whatever a file's name says."""

    hashes: frozenset[str]
    tracks: TrackIndex

    @classmethod
    def read(cls, suite_dir: Path | None) -> HiddenTracks:
        if suite_dir is None:
            return cls(frozenset(), TrackIndex())
        path = Path(suite_dir) / "manifest.json"
        if not path.is_file():
            raise DatasetError(f"{suite_dir}: not a built suite (no manifest.json)")
        scenes = json.loads(path.read_text()).get("naturalistic_scenes") or []
        # Suites built before vehicles were listed have no tracks file: files by sha256 only.
        tracks_path = Path(suite_dir) / TRACKS_FILE
        per_scene = json.loads(tracks_path.read_text()) if tracks_path.is_file() else {}
        tracks = TrackIndex()
        for scene, scene_tracks in per_scene.items():
            tracks.add(scene, {track["vehicle"]: track["poses"] for track in scene_tracks})
        return cls(frozenset(s["sha256"] for s in scenes), tracks)

    def shared(self, scene: CorpusScene) -> str | None:
        """Why ``scene`` must stay out of a dataset (it or one of its vehicles is in the
        suite), or None."""
        if scene.sha256() in self.hashes:
            return "the suite used this file"
        for vehicle, same in sorted(self.tracks.same_vehicles(scene.tracks()).items()):
            if same:
                hidden_scene, hidden_vehicle = sorted(same)[0]
                return (
                    f"vehicle {vehicle} is vehicle {hidden_vehicle} of {hidden_scene}, "
                    "which the suite used"
                )
        return None


@dataclass(frozen=True)
class Source:
    """A replay scenario to collect episodes from, and the manifest facts of its episodes."""

    folder: Path
    facts: dict


def _sources(
    corpus: Corpus | None, public_dir: Path | None, hidden: HiddenTracks, work: Path
) -> tuple[list[Source], list[dict], list[CorpusScene]]:
    """The scenarios to collect, the scene files left out (file and reason) and the corpus
    scenes the scenarios are cut from."""
    out, left_out, used = [], [], []
    if corpus is not None:
        seen: set = set()  # vehicle identities already an episode (scenes of one recording)
        for s in corpus.scenes:
            reason = hidden.shared(s)
            if reason is not None:
                left_out.append({"file": s.file, "reason": reason})
                continue
            for ego in s.egos:
                identity = corpus.identity[(s.file, ego.vehicle_id)]
                if identity in seen:
                    continue
                seen.add(identity)
                sid = f"{Path(s.file).stem}_{ego.vehicle_id}"
                folder = work / f"{len(out):05d}-{sid}"  # ids of two files may coincide
                write_naturalistic(folder, sid, s.scene, ego, s.net, seed=0)
                facts = {
                    "source": s.scene.provenance.source,
                    "label": s.scene.provenance.label.value,
                    "scene": s.scene.name,
                    "file": s.file,
                    "vehicle": ego.vehicle_id,
                }
                out.append(Source(folder, facts))
                if not used or used[-1] is not s:
                    used.append(s)
    if public_dir is not None:
        for folder in sorted(p for p in Path(public_dir).iterdir() if p.is_dir()):
            scenario = load_scenario(folder)
            if scenario.traffic.kind == "replay" and not scenario.reactive:
                out.append(
                    Source(folder, {"source": DataLabel.recorded.value, "scene": scenario.id})
                )
    return out, left_out, used


def build_dataset(
    out: Path,
    cache_dir: Path,
    scenes_dir: Path | None,
    public_dir: Path | None,
    exclude_suite: Path | None = None,
    progress: Callable[[str], None] = lambda _: None,
    *,
    label: DataLabel | None = None,
    licence: Path | None = None,
    jobs: int = 1,
    on_sources: Callable[[int], None] = lambda _: None,
) -> dict:
    """Write the Minari dataset :data:`DATASET_ID` under ``out`` (its ``MINARI_DATASETS_PATH``)
    plus ``out/dataset-manifest.json``; returns the manifest. ``progress`` is told each scene
    file read and each scenario collected; ``on_sources`` how many scenarios will be. ``jobs``
    scene files are read and scenarios collected at once."""
    # deferred: heavy optional dependencies (the dataset extra), loaded only when building
    import gymnasium as gym
    import minari
    from minari.data_collector import EpisodeBuffer

    out = Path(out).resolve()  # minari resolves its own path against another folder
    hidden = HiddenTracks.read(exclude_suite)
    corpus = (
        read_corpus(
            scenes_dir,
            Path(cache_dir) / "naturalistic",
            label=label,
            licence=licence,
            jobs=jobs,
            progress=progress,
        )
        if scenes_dir is not None
        else None
    )
    rows: list[dict] = []
    buffers = []
    episodes: list[Episode] = []
    unsolved: list[dict] = []
    with tempfile.TemporaryDirectory(prefix="arena-dataset-") as tmp:
        sources, left_out, used = _sources(corpus, public_dir, hidden, Path(tmp))
        if not sources:
            raise DatasetError(_nothing_left(corpus, left_out))
        on_sources(len(sources))
        # Each episode runs in its own simulator process: threads only wait for them.
        with ThreadPoolExecutor(max_workers=jobs) as pool:
            collected = pool.map(collect, [source.folder for source in sources])
            for source, (folder_episodes, reason) in zip(sources, collected, strict=True):
                _add(folder_episodes, source.facts, episodes, buffers, rows, EpisodeBuffer)
                if reason is not None:
                    unsolved.append({**source.facts, "reason": reason})
                progress(source.folder.name)
    if not rows:
        first = unsolved[0]["reason"] if unsolved else "each ended before its second step"
        raise DatasetError(
            f"no episode left: the log replay expert finished none of the {len(sources)} "
            f"scenarios (first: {first})"
        )
    out.mkdir(parents=True, exist_ok=True)
    os.environ["MINARI_DATASETS_PATH"] = str(out)  # where minari writes and looks up datasets
    if DATASET_ID in minari.list_local_datasets():
        minari.delete_dataset(DATASET_ID)
    space = gym.spaces.Box(-np.inf, np.inf, (OBS_SIZE,), np.float32)
    with warnings.catch_warnings():
        # minari warns about optional metadata we have none of (permalink, e-mail, eval env).
        warnings.filterwarnings("ignore", category=UserWarning, module="minari")
        _create(minari, buffers, space, sorted({row["source"] for row in rows}))
    manifest = {
        "dataset_id": DATASET_ID,
        "episodes": rows,
        "scenes": [  # the scene files the episodes were cut from, by content and name
            {
                "file": s.file,
                "sha256": s.sha256(),
                "scene": s.scene.name,
                "origin": list(s.scene.origin),
            }
            for s in used
            if any(row.get("file") == s.file for row in rows)
        ],
        "unsolved": unsolved,
        "excluded_scenes": left_out,
        "skipped_scenes": [{"file": k.file, "reason": k.reason} for k in corpus.skipped]
        if corpus is not None
        else [],
        "rejected_vehicles": corpus.rejected() if corpus is not None else {},
        "observation_size": OBS_SIZE,
        "action_size": ACTION_SIZE,
    }
    write_transitions(out / TRANSITIONS, episodes)
    (out / MANIFEST).write_text(json.dumps(manifest, indent=2) + "\n")
    return manifest


def _add(new: list[Episode], facts: dict, episodes: list, buffers: list, rows: list, cls) -> None:
    """Append ``new`` episodes of one scenario with their manifest rows (``facts``)."""
    for episode in new:
        episodes.append(episode)
        buffers.append(_buffer(cls, len(buffers), episode))
        rows.append(
            {
                "episode": len(rows),
                "scenario": episode.scenario_id,
                "agent": episode.agent_id,
                "steps": len(episode.actions),
                **facts,
            }
        )


def _nothing_left(corpus: Corpus | None, left_out: list[dict]) -> str:
    if corpus is None:
        return "no source: give a scenes folder or include the public replays"
    unusable = "; ".join(f"{k.file}: {k.reason}" for k in corpus.skipped[:10])
    return (
        f"no episode left: {len(left_out)} scene files share vehicles with the excluded suite, "
        f"{len(corpus.skipped)} are unusable{f' ({unusable})' if unusable else ''}, "
        f"{corpus.rejected() or 'no'} vehicles rejected "
        "(a dataset needs scenes the hidden suite did not use)"
    )


def write_transitions(path: Path, episodes: list[Episode]) -> None:
    """Every transition of every episode, one row each (docs/dataset.md: `transitions.npz`)."""
    empty_obs = np.zeros((0, OBS_SIZE), np.float32)
    np.savez_compressed(
        path,
        observations=np.concatenate([e.observations[:-1] for e in episodes] or [empty_obs]),
        next_observations=np.concatenate([e.observations[1:] for e in episodes] or [empty_obs]),
        actions=np.concatenate(
            [e.actions for e in episodes] or [np.zeros((0, ACTION_SIZE), np.float32)]
        ),
        rewards=np.concatenate([e.rewards for e in episodes] or [np.zeros(0)]),
        terminations=np.concatenate([e.terminations for e in episodes] or [np.zeros(0, bool)]),
        truncations=np.concatenate([e.truncations for e in episodes] or [np.zeros(0, bool)]),
        episode=np.concatenate(
            [np.full(len(e.actions), i, np.int32) for i, e in enumerate(episodes)]
            or [np.zeros(0, np.int32)]
        ),
    )


def _buffer(cls, index: int, episode: Episode):
    return cls(
        id=index,
        observations=list(episode.observations),
        actions=list(episode.actions),
        rewards=episode.rewards.tolist(),
        terminations=episode.terminations.tolist(),
        truncations=episode.truncations.tolist(),
        infos={},
    )


def _create(minari, buffers: list, space, sources: list[str]) -> None:
    # deferred: heavy optional dependencies (the dataset extra), loaded only when building
    import gymnasium as gym

    minari.create_dataset_from_buffers(
        DATASET_ID,
        buffers,
        observation_space=space,
        action_space=gym.spaces.Box(-np.inf, np.inf, (ACTION_SIZE,), np.float32),
        algorithm_name="log replay expert",
        author="Driving Arena",
        description=(
            f"Driving Arena replays from: {', '.join(sources)}. Each episode's source and scene "
            "are in dataset-manifest.json; licences and attribution in docs/dataset.md."
        ),
        data_format="hdf5",
    )
