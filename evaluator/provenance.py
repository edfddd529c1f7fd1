"""What a score depends on besides the agent: the reproducibility manifest.

A score is reproducible when everything that went into it is pinned: the submission's bytes (and,
on Track 2, the trained model's), the suite and each scenario's content, the traffic seed of every
episode, the scoring profile, and the software that ran it (this project's version, Python,
numpy, SUMO, the sandbox and the agent image, and the numerical stack the agent imported inside
its sandbox). The manifest names each by version or sha256, so
a re-run can first check it runs under the same conditions (:func:`differences`) and then compare
records bit for bit.
"""

from __future__ import annotations

import hashlib
import platform
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from functools import lru_cache
from importlib import metadata

import numpy as np
from pydantic import BaseModel, ConfigDict

from arena.scenario import content_hash
from arena.suite import Suite

PROJECT = "driving-arena"


class Frozen(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")


class Environment(Frozen):
    """The software an episode ran under."""

    arena: str  # this project's version
    python: str
    numpy: str
    sumo: str
    sandbox: str  # the backend that ran the agent: docker, bubblewrap or process
    # Docker: the agent image's id (sha256); other backends run the agent on the worker's own
    # runtime, which the versions above pin.
    agent_image: str | None = None
    # What the agent computed with, as imported inside its sandbox: Python and each numerical
    # library it loaded (numpy, torch, ...) by module name, as the runtime there reported them
    # (a submission's requirements choose its own numpy; ``numpy`` above is the evaluator's).
    # A result of the run, not a condition of it: a re-run is not refused over it.
    agent_stack: dict[str, str] = {}

    def __hash__(self) -> int:  # frozen, but the dict field has no hash of its own
        return hash(self.model_dump_json())


class ScenarioPin(Frozen):
    hash: str  # sha256 of the scenario folder (arena.scenario.content_hash)
    seeds: tuple[int, ...]  # the SUMO traffic seed of each episode (arena.episodes)


class SeedModel(Frozen):
    """One training seed's model behind a score over several seeds."""

    seed: int  # ARENA_TRAIN_SEED
    model: str  # sha256 of the model trained with it


class Manifest(Frozen):
    """Everything a score depends on, by version or sha256."""

    submission: str  # sha256 of the uploaded zip
    model: str | None = None  # Track 2: sha256 of the trained model the agent ran with
    # Track 2 over several training seeds (model is then None): each seed's model, seed order.
    seed_models: tuple[SeedModel, ...] = ()
    suite: str
    suite_hash: str  # sha256 of the suite's manifest.json
    scenarios: dict[str, ScenarioPin]  # charged and uncharged alike, in manifest order
    episodes_per_scenario: int = 1
    profile: str
    profile_version: str
    # The distinct environments the episodes ran under: one when every worker was alike.
    environments: tuple[Environment, ...]

    def public(self) -> PublicManifest:
        """What a team may see: no scenario ids and no seeds of a hidden suite, only their
        digests (the scenario hashes, sorted, identify contents without naming them)."""
        pins = sorted(self.scenarios.values(), key=_by_hash)
        return PublicManifest(
            **self.model_dump(exclude={"scenarios"}),
            scenario_hashes=tuple(pin.hash for pin in pins),
            seeds_sha256=_digest([[pin.hash, *pin.seeds] for pin in pins]),
        )


class PublicManifest(Frozen):
    """:class:`Manifest` as a team sees it."""

    submission: str
    model: str | None
    seed_models: tuple[SeedModel, ...] = ()
    suite: str
    suite_hash: str
    scenario_hashes: tuple[str, ...]  # sorted
    seeds_sha256: str  # over each scenario's hash and episode seeds
    episodes_per_scenario: int
    profile: str
    profile_version: str
    environments: tuple[Environment, ...]


def over_seeds(manifests: Mapping[int, Manifest]) -> Manifest:
    """The manifest of a score over training seeds, from each seed's run's (keyed by seed): the
    submission, suite, scenarios, seeds and profile they share (a set's runs are on one suite,
    checked when it is scored), each seed's model, and every environment any of them ran under."""
    if not manifests:
        raise ValueError("a score over seeds needs at least one seed's manifest")
    first = manifests[min(manifests)]
    return first.model_copy(
        update={
            "model": None,
            "seed_models": tuple(
                SeedModel(seed=seed, model=manifests[seed].model or "")
                for seed in sorted(manifests)
            ),
            "environments": distinct(
                env for seed in sorted(manifests) for env in manifests[seed].environments
            ),
        }
    )


def _by_hash(pin: ScenarioPin) -> str:
    return pin.hash


def _digest(value: object) -> str:
    return hashlib.sha256(repr(value).encode()).hexdigest()


# Components a re-run must match before records are compared, each with what it covers.
COMPONENTS = {
    "submission": "the submission's bytes",
    "model": "the trained model",
    "suite_hash": "the suite manifest",
    "scenarios": "the scenarios' contents or seeds",
    "episodes_per_scenario": "the episodes per reactive scenario",
    "profile": "the scoring profile",
    "profile_version": "the scoring profile's version",
}
ENVIRONMENT_FIELDS = ("arena", "python", "numpy", "sumo", "sandbox", "agent_image")


def differences(recorded: Manifest, current: Manifest) -> list[str]:
    """The components of ``current`` that differ from ``recorded``, named (empty: the same
    conditions). Environments differ when the re-run's is not among the recorded ones."""
    names = [
        f"{name} ({what}): {_short(getattr(recorded, name))} -> {_short(getattr(current, name))}"
        for name, what in COMPONENTS.items()
        if getattr(recorded, name) != getattr(current, name)
    ]
    for env in current.environments:
        if env in recorded.environments:
            continue
        for field in ENVIRONMENT_FIELDS:
            before = {getattr(e, field) for e in recorded.environments}
            if getattr(env, field) not in before:
                was = ", ".join(sorted(str(v) for v in before))
                names.append(f"environment.{field}: {was} -> {getattr(env, field)}")
    return names


def _short(value: object) -> str:
    text = str(value) if not isinstance(value, Mapping) else f"{len(value)} scenarios"
    return text if len(text) <= 80 else text[:77] + "..."


def distinct(environments: Iterable[Environment | None]) -> tuple[Environment, ...]:
    """Each environment once, in first-seen order (episodes without one are left out)."""
    seen: list[Environment] = []
    for env in environments:
        if env is not None and env not in seen:
            seen.append(env)
    return tuple(seen)


@dataclass(frozen=True)
class EpisodeRun:
    """What one finished episode tells the manifest."""

    scenario_id: str
    episode: int
    seed: int | None  # None: an episode from before seeds were kept
    environment: Environment | None


def manifest_of(
    suite: Suite,
    episodes: Iterable[EpisodeRun],
    *,
    submission: str,
    model: str | None,
    episodes_per_scenario: int,
    profile: str,
    profile_version: str,
) -> Manifest:
    """The manifest of an evaluation of ``suite`` from its finished episodes: the seeds and
    environments are what the episodes actually ran with."""
    episodes = sorted(episodes, key=lambda e: (e.scenario_id, e.episode))
    seeds: dict[str, list[int]] = {}
    for run in episodes:
        if run.seed is not None:
            seeds.setdefault(run.scenario_id, []).append(run.seed)
    return Manifest(
        submission=submission,
        model=model,
        suite=suite.name,
        suite_hash=suite.sha256,
        scenarios={
            entry.id: ScenarioPin(
                hash=entry.hash or content_hash(suite.scenario_dir(entry.id)),
                seeds=tuple(seeds.get(entry.id, ())),
            )
            for entry in suite.scenarios
        },
        episodes_per_scenario=episodes_per_scenario,
        profile=profile,
        profile_version=profile_version,
        environments=distinct(run.environment for run in episodes),
    )


def environment(
    sandbox: str, agent_image: str, agent_stack: Mapping[str, str] | None = None
) -> Environment:
    """The environment an episode run now, here, with backend ``sandbox`` (and, with Docker,
    the image ``agent_image``) would have; ``agent_stack``: what its agent reported importing."""
    image = _docker_image_id(agent_image) if sandbox == "docker" else None
    versions = _versions(sandbox, image)
    if not agent_stack:
        return versions
    return versions.model_copy(update={"agent_stack": dict(agent_stack)})


@lru_cache(maxsize=8)
def _versions(sandbox: str, agent_image: str | None) -> Environment:
    return Environment(
        arena=_version(PROJECT),
        python=platform.python_version(),
        numpy=np.__version__,
        sumo=_sumo_version(),
        sandbox=sandbox,
        agent_image=agent_image,
    )


def _version(distribution: str) -> str:
    try:
        return metadata.version(distribution)
    except metadata.PackageNotFoundError:
        return "unknown"


def _sumo_version() -> str:
    for distribution in ("eclipse-sumo", "libsumo"):
        version = _version(distribution)
        if version != "unknown":
            return version
    return "unknown"


def _docker_image_id(image: str) -> str | None:
    """The id (sha256 of its configuration) of the image, or None when Docker cannot say. Asked
    per episode, since the image may be rebuilt during an evaluation, through the process's one
    client (a new client per episode cost more than the question)."""
    import docker.errors  # only where Docker is the backend

    from evaluator.sandbox.docker_backend import docker_client

    try:
        return docker_client().images.get(image).id
    except docker.errors.DockerException:
        return None
