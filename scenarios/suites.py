"""The hidden suite (128 scenarios, composition of the scenario spec) and the public set.

A suite is a pure function of (suite, seed): every scenario's traffic seed is derived from a
domain-separated hash of the suite name, the suite seed and the scenario's row, so a public
scenario never equals a hidden one and the hidden seed cannot be recovered from a public build.
The hidden seed itself is never written anywhere: the manifest carries its fingerprint.
"""

from __future__ import annotations

import json
import shutil
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from arena.scenario import DataLabel, Family, Scenario, content_hash
from arena.suite import ManifestEntry, SuiteManifest, write_manifest
from scenarios.generators import GENERATORS, MapLibrary, Spec
from scenarios.ids import derive_seed, scenario_id, seed_fingerprint
from scenarios.maps import netconvert_version
from scenarios.recorded.builder import Candidate, candidates, write_replay
from scenarios.recorded.naturalistic_pool import TRACKS_FILE, NaturalisticPool
from scenarios.recorded.recorder import Recording
from scenarios.recorded.scenes import SCENES, recorded
from scenarios.variants import KIND_SCENE, VARIANTS
from scenarios.verify import replay_unsolved
from scenarios.writer import write_reactive

PUBLIC_SEED = 2022
BUBBLE_RADIUS = 40.0  # [m]

LOW_MID = ("low", "mid")


# Reactive composition (scenario spec, "Reactive scenarios (71)").
def every_variant(family: Family) -> tuple[str, ...]:
    """The family's variants in the order of the variant table (suite ids depend on it)."""
    return tuple(VARIANTS[family])


REACTIVE: tuple[tuple[Family, tuple[str, ...], tuple[str | None, ...], tuple[int, ...]], ...] = (
    (Family.left_turn_t, every_variant(Family.left_turn_t), LOW_MID, (1,)),
    (Family.turn_c, every_variant(Family.turn_c), LOW_MID, (1,)),
    (Family.merge, every_variant(Family.merge), LOW_MID, (1, 2)),
    (Family.cruise, every_variant(Family.cruise), ("low", "high"), (1,)),
    (Family.cruise, ("2lane",), ("low", "high"), (2,)),
    (Family.cruise, ("3lane_curve",), ("low", "high"), (3,)),
    (Family.cut_in, every_variant(Family.cut_in), ("mid",), (1,)),
    (Family.overtake, every_variant(Family.overtake), LOW_MID, (1,)),
)
# Non-reactive replays (scenario spec, "Non-reactive replays (57)"): (kind, agents, count).
REPLAYS: tuple[tuple[str, int, int], ...] = (
    ("cruise", 1, 18),
    ("lane_change", 1, 11),
    ("merge", 1, 7),
    ("merge", 2, 6),
    ("overtake", 1, 4),
    ("right_turn", 1, 7),
    ("left_turn", 1, 2),
    ("cut_off", 1, 1),
    ("urban", 1, 1),
)
BUBBLE = Spec(Family.replay, "i80_bubble", None, 1, reactive=True)


def hidden_specs() -> list[Spec]:
    specs = [
        Spec(family, variant, volume, agents)
        for family, variants, volumes, agent_counts in REACTIVE
        for variant in variants
        for agents in agent_counts
        for volume in volumes
    ]
    specs.append(BUBBLE)
    for kind, agents, count in REPLAYS:
        specs += [Spec(Family.replay, kind, None, agents, reactive=False)] * count
    return specs


def public_specs() -> list[Spec]:
    """One scenario per family/variant group (alternating volumes), plus every replay kind."""
    specs = []
    for family, variants, volumes, agent_counts in REACTIVE:
        for i, variant in enumerate(variants):
            agents = agent_counts[i % len(agent_counts)]
            specs.append(Spec(family, variant, volumes[i % len(volumes)], agents))
    specs.append(BUBBLE)
    specs += [
        Spec(Family.replay, kind, None, agents, reactive=False) for kind, agents, _ in REPLAYS
    ]
    return specs


SUITES: dict[str, Callable[[], list[Spec]]] = {"hidden": hidden_specs, "public": public_specs}


MAX_TAKES_PER_SCENE = 4  # recordings of one scene per build before giving up on a kind


@dataclass
class _ReplayPool:
    """Removable vehicles per kind, cut from scenes recorded for this build and handed out
    without reuse; a scene whose recordings run out of a kind is recorded again (next take)."""

    suite: str
    seed: int
    maps: MapLibrary
    takes: dict[str, list[tuple[Recording, dict[str, list[Candidate]]]]] = field(
        default_factory=dict
    )
    used: set[tuple[int, str]] = field(default_factory=set)

    def take(
        self, kind: str, agents: int, rng: np.random.Generator
    ) -> tuple[str, Recording, Candidate]:
        scene = KIND_SCENE[kind]
        pool_name = "merge_pair" if agents > 1 else kind
        takes = self.takes.setdefault(scene, [])
        for take in range(MAX_TAKES_PER_SCENE):
            if take == len(takes):
                takes.append(self._record(scene, take))
            rec, pools = takes[take]
            free = [
                c
                for c in pools.get(pool_name, [])
                if not self.used.intersection((take, v) for v in c.vehicle_ids)
            ]
            if free:
                chosen = free[int(rng.integers(len(free)))]
                self.used.update((take, v) for v in chosen.vehicle_ids)
                return scene, rec, chosen
        raise RuntimeError(f"scene {scene!r} has no unused {kind!r} vehicle left")

    def write(
        self, folder: Path, sid: str, spec: Spec, rng: np.random.Generator, seed: int
    ) -> Scenario:
        """Replay row ``sid`` (``spec``) at ``folder``; a non-reactive one from the first drawn
        vehicles whose recorded drive the log replay expert finishes."""
        while True:
            scene, recording, chosen = self.take(spec.variant, spec.agents, rng)
            scenario = write_replay(
                folder,
                sid,
                spec.variant,
                recording,
                chosen,
                self.maps.path(SCENES[scene].template),
                seed,
                BUBBLE_RADIUS if spec.reactive else None,
            )
            if spec.reactive or replay_unsolved(folder, self.maps.cache_dir) is None:
                return scenario
            shutil.rmtree(folder)

    def _record(self, scene: str, take: int) -> tuple[Recording, dict[str, list[Candidate]]]:
        parts = ("scene", scene) if take == 0 else ("scene", scene, take)
        rec = recorded(SCENES[scene], derive_seed(self.suite, self.seed, *parts), self.maps)
        info = self.maps.info(SCENES[scene].template)
        return rec, candidates(rec, info, scene, SCENES[scene].duration_s)


@dataclass(frozen=True)
class CorpusOptions:
    """An organiser's folder of CommonRoad / NGSIM CSV scenes for a suite build, with what they
    state of its provenance (``label``, a ``licence`` file) and how many processes read it."""

    folder: Path
    label: DataLabel | None = None
    licence: Path | None = None
    jobs: int = 1
    progress: Callable[[str], None] = lambda _: None  # told each scene file read


def build_suite(
    suite: str,
    seed: int,
    out: Path,
    cache_dir: Path,
    progress: Callable[[str], None] = lambda _: None,
    naturalistic_dir: Path | CorpusOptions | None = None,
) -> SuiteManifest:
    """Write every scenario of ``suite`` under ``out`` plus ``manifest.json``; returns the
    manifest. ``out`` is replaced. With ``naturalistic_dir`` (a folder of CommonRoad / NGSIM CSV
    scenes) the one-agent non-reactive replay rows of each kind are drawn from its recorded
    vehicles of that kind while they last (:mod:`scenarios.recorded.naturalistic_pool`). Every
    non-reactive replay, corpus or ours, enters the suite only once the log replay expert has
    finished it: nothing unsolvable is drawn."""
    specs = SUITES[suite]()
    if isinstance(naturalistic_dir, Path):
        naturalistic_dir = CorpusOptions(naturalistic_dir)
    # Read every scene before touching ``out``: a folder with no usable mission fails up front.
    natural = (
        NaturalisticPool.load(
            naturalistic_dir.folder,
            suite,
            seed,
            cache_dir,
            label=naturalistic_dir.label,
            licence=naturalistic_dir.licence,
            jobs=naturalistic_dir.jobs,
            progress=naturalistic_dir.progress,
        )
        if naturalistic_dir is not None
        else None
    )
    if out.exists():
        shutil.rmtree(out)
    out.mkdir(parents=True)
    maps = MapLibrary(cache_dir)
    replays = _ReplayPool(suite, seed, maps)
    entries = []
    for index, spec in enumerate(specs):
        sid = scenario_id(suite, index, spec)
        scenario_seed = derive_seed(suite, seed, index, spec.family, spec.variant, spec.volume)
        rng = np.random.default_rng(scenario_seed)
        folder = out / sid
        written = (
            natural.write(out, suite, index, spec, scenario_seed)
            if natural is not None and natural.takes(spec)
            else None
        )
        if written is not None:
            scenario, source = written
            entries.append(manifest_entry(scenario, out / scenario.id, source))
            progress(scenario.id)
            continue
        if spec.family is Family.replay:
            scenario = replays.write(folder, sid, spec, rng, scenario_seed)
        else:
            draft = GENERATORS[spec.family](spec, rng, maps)
            scenario = write_reactive(
                folder, sid, spec, scenario_seed, draft, maps.path(draft.template)
            )
        entries.append(manifest_entry(scenario, folder))
        progress(sid)
    manifest = SuiteManifest(
        suite=suite,
        netconvert=netconvert_version(),
        scenarios=tuple(entries),
        naturalistic_scenes=natural.scene_list() if natural is not None else None,
        naturalistic_skipped=natural.skipped_list() if natural is not None else None,
        naturalistic_rejected=natural.corpus.rejected() if natural is not None else None,
        naturalistic_unsolved=tuple(natural.unsolved) if natural is not None else None,
        seed=seed if suite == "public" else None,
        seed_fingerprint=None if suite == "public" else seed_fingerprint(seed),
    )
    if natural is not None:
        (out / TRACKS_FILE).write_text(json.dumps(natural.track_list()) + "\n")
    write_manifest(out, manifest)
    return manifest


def manifest_entry(scenario: Scenario, folder: Path, source: str | None = None) -> ManifestEntry:
    return ManifestEntry(
        id=scenario.id,
        family=scenario.family,
        variant=scenario.variant,
        volume=scenario.volume,
        agents=scenario.agents,
        reactive=scenario.reactive,
        hash=content_hash(folder),
        label=scenario.label,
        unsolvable_reason=scenario.unsolvable_reason,
        source=source,
    )
