"""`arena dataset build`: recorded and naturalistic replays -> a Minari offline-RL dataset.

Sources: the naturalistic scenes (one episode per ego choice of every scene, see
:mod:`scenarios.recorded.naturalistic`) and the non-reactive replays of the public set (our SUMO
recordings). Scenes that a hidden suite used (its manifest's ``naturalistic_scenes``, matched by
sha256) are left out. ``DIR/dataset-manifest.json`` says which scenes and vehicles it holds.
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
import warnings
from collections.abc import Callable
from pathlib import Path

import numpy as np

from arena.scenario import DataLabel, load_scenario
from scenarios.dataset.collect import Episode, collect
from scenarios.dataset.features import ACTION_SIZE, OBS_SIZE
from scenarios.recorded.naturalistic import ego_choices, load_scenes, scene_net, write_naturalistic

DATASET_ID = "driving-arena/replays-v0"
MANIFEST = "dataset-manifest.json"
# The same transitions as plain numpy arrays: what a Track 2 train.py reads in the sandbox, which
# has numpy but neither minari nor h5py.
TRANSITIONS = "transitions.npz"


def hidden_scene_hashes(suite_dir: Path | None) -> set[str]:
    if suite_dir is None:
        return set()
    manifest = json.loads((Path(suite_dir) / "manifest.json").read_text())
    return {s["sha256"] for s in manifest.get("naturalistic_scenes", [])}


def _sources(
    scenes_dir: Path | None, public_dir: Path | None, excluded: set[str], work: Path, cache: Path
) -> tuple[list[tuple[Path, dict]], list[str]]:
    """(scenario folder, manifest facts) per source scenario, and the scene files left out."""
    out, left_out = [], []
    if scenes_dir is not None:
        for scene in load_scenes(scenes_dir):
            if hashlib.sha256(scene.source_file.read_bytes()).hexdigest() in excluded:
                left_out.append(scene.source_file.name)
                continue
            net = scene_net(scene, cache)
            for ego in ego_choices(scene, net):
                folder = work / f"{scene.name}_{ego.vehicle_id}"
                write_naturalistic(folder, folder.name, scene, ego, net, seed=0)
                facts = {"source": "NGSIM", "scene": scene.name, "vehicle": ego.vehicle_id}
                out.append((folder, facts))
    if public_dir is not None:
        for folder in sorted(p for p in Path(public_dir).iterdir() if p.is_dir()):
            scenario = load_scenario(folder)
            if scenario.traffic.kind == "replay" and not scenario.reactive:
                out.append((folder, {"source": DataLabel.recorded.value, "scene": scenario.id}))
    return out, left_out


def build_dataset(
    out: Path,
    cache_dir: Path,
    scenes_dir: Path | None,
    public_dir: Path | None,
    exclude_suite: Path | None = None,
    progress: Callable[[str], None] = lambda _: None,
) -> dict:
    """Write the Minari dataset :data:`DATASET_ID` under ``out`` (its ``MINARI_DATASETS_PATH``)
    plus ``out/dataset-manifest.json``; returns the manifest."""
    # deferred: heavy optional dependencies (the dataset extra), loaded only when building
    import gymnasium as gym
    import minari
    from minari.data_collector import EpisodeBuffer

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    excluded = hidden_scene_hashes(exclude_suite)
    rows: list[dict] = []
    buffers = []
    episodes: list[Episode] = []
    with tempfile.TemporaryDirectory(prefix="arena-dataset-") as tmp:
        sources, left_out = _sources(
            scenes_dir, public_dir, excluded, Path(tmp), Path(cache_dir) / "naturalistic"
        )
        for folder, facts in sources:
            for episode in collect(folder):
                episodes.append(episode)
                buffers.append(_buffer(EpisodeBuffer, len(buffers), episode))
                rows.append(
                    {
                        "episode": len(rows),
                        "scenario": episode.scenario_id,
                        "agent": episode.agent_id,
                        "steps": len(episode.actions),
                        **facts,
                    }
                )
            progress(folder.name)
    os.environ["MINARI_DATASETS_PATH"] = str(out)  # where minari writes and looks up datasets
    if DATASET_ID in minari.list_local_datasets():
        minari.delete_dataset(DATASET_ID)
    space = gym.spaces.Box(-np.inf, np.inf, (OBS_SIZE,), np.float32)
    with warnings.catch_warnings():
        # minari warns about optional metadata we have none of (permalink, e-mail, eval env).
        warnings.filterwarnings("ignore", category=UserWarning, module="minari")
        _create(minari, buffers, space)
    manifest = {
        "dataset_id": DATASET_ID,
        "episodes": rows,
        "excluded_scenes": left_out,
        "observation_size": OBS_SIZE,
        "action_size": ACTION_SIZE,
    }
    write_transitions(out / TRANSITIONS, episodes)
    (out / MANIFEST).write_text(json.dumps(manifest, indent=2) + "\n")
    return manifest


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


def _create(minari, buffers: list, space) -> None:
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
            "Driving Arena replays: NGSIM (via CommonRoad, TU Munich, BSD 3-Clause; roads partly "
            "(c) OpenStreetMap contributors, ODbL) and SUMO-recorded traffic. See docs/dataset.md."
        ),
        data_format="hdf5",
    )
