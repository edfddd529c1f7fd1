"""Auditing a score: re-run a scored submission under its manifest and compare record by record.

The manifest (evaluator/provenance.py) pins what the score depends on. An audit first rebuilds
that manifest from what is here now: the stored upload's and model's bytes, the suite on disk,
every episode's traffic seed, this machine's software. Any component that differs is named and
nothing is re-run (a different SUMO would make a difference that says nothing about the score).
Otherwise every scored episode runs again, in its sandbox, and its outcome and record are
compared with the stored ones: bit-identical, or the first record that differs and where. A
score over several training seeds is audited seed by seed (each seed's model on its own run), and
what differs is named with its seed.
"""

from __future__ import annotations

import dataclasses
import random
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from sqlalchemy import select
from sqlalchemy.orm import Session

from arena.config import IntakeSettings, SandboxKind, SandboxSettings
from arena.cpu_limits import CpuLimits
from arena.episodes import Episode, traffic_seed
from arena.errors import ArenaError
from arena.files import file_sha256
from arena.outcome import FINISHED
from arena.scenario import load_scenario
from arena.suite import Suite, load_suite
from evaluator import sandbox
from evaluator.provenance import EpisodeRun, Manifest, differences, environment, manifest_of
from evaluator.runner import ScenarioOutcome, run_scenario
from evaluator.sandbox.warm_pool import warm_agents
from evaluator.training import unpack_model
from evaluator.validation import validate
from server.core.artifacts import ArtifactStore, MissingArtifact
from server.core.db import Database
from server.models import EvaluationRun, Phase, ScenarioResult, SeedSetScore, Submission
from server.services.errors import Conflict, NotFound
from server.services.evaluation import run_cpu_limits
from server.services.leaderboard import compute
from server.services.seed_sets import standing_score
from server.services.submissions import current_run
from server.status import RunStatus
from server.tracks import Track


@dataclass(frozen=True)
class AuditReport:
    submission_id: int
    refused: tuple[str, ...] = ()  # the manifest components that differ: nothing was re-run
    compared: int = 0  # episodes re-run and compared
    difference: str | None = None  # the first record (or outcome) that differs, and where

    @property
    def identical(self) -> bool:
        return not self.refused and self.difference is None


@dataclass(frozen=True)
class _Stored:
    """A scored episode as the database keeps it."""

    scenario_id: str
    episode: int
    status: str
    agents: list[dict]
    record_key: str | None


@dataclass(frozen=True)
class _Target:
    submission_id: int
    manifest: Manifest
    suite_dir: Path
    upload_key: str
    model_key: str | None
    episodes: tuple[_Stored, ...]
    limits: CpuLimits  # the agent's CPU limits the run was evaluated under
    label: str  # which of the score's runs: "" for a score of one run, "seed K: " over seeds


def _targets(session: Session, config: SandboxSettings, submission_id: int) -> list[_Target]:
    """The runs the standing score comes from: one, or each training seed's."""
    submission = session.get(Submission, submission_id)
    if submission is None:
        raise NotFound(f"no submission {submission_id}")
    score = standing_score(submission)
    if isinstance(score, SeedSetScore):
        return [
            _target(
                session,
                config,
                submission,
                session.get(EvaluationRun, seed["run_id"]),
                f"seed {seed['seed']}: ",
            )
            for seed in score.per_seed
        ]
    run = current_run(submission)
    if run is None or run.status != RunStatus.scored or run.score is None:
        raise Conflict(f"submission {submission_id} has no score to audit")
    return [_target(session, config, submission, run, "")]


def _target(
    session: Session,
    config: SandboxSettings,
    submission: Submission,
    run: EvaluationRun,
    label: str,
) -> _Target:
    submission_id = submission.id
    if not run.score.manifest:
        raise Conflict(
            f"submission {submission_id} was scored before manifests were kept: "
            "`arena admin rerun` it first"
        )
    results = session.scalars(
        select(ScenarioResult)
        .where(ScenarioResult.run_id == run.id)
        .order_by(ScenarioResult.scenario_id, ScenarioResult.episode)
    )
    return _Target(
        submission_id=submission_id,
        manifest=Manifest.model_validate(run.score.manifest),
        suite_dir=Path(run.suite_dir),
        upload_key=submission.upload_key,
        model_key=run.training.model_key if run.training is not None else None,
        episodes=tuple(
            _Stored(r.scenario_id, r.episode, r.status, r.detail.get("agents", []), r.record_key)
            for r in results
            if r.status in FINISHED
        ),
        limits=run_cpu_limits(run, config),
        label=label,
    )


def audit(
    db: Database,
    store: ArtifactStore,
    submission_id: int,
    *,
    intake: IntakeSettings,
    config: SandboxSettings,
    data_dir: Path,
    progress: Callable[[int, int], None] | None = None,
) -> AuditReport:
    """Re-run ``submission_id``'s scored episodes under its manifest (each seed's, for a score
    over training seeds) as a worker runs them (``intake``, ``config``, ``data_dir``: as
    :func:`evaluator.runner.evaluate` takes them); ``progress(done, total)`` after each episode.
    The first refusal or difference ends the audit."""
    with db.read_session() as session:
        targets = _targets(session, config, submission_id)
    total = sum(len(target.episodes) for target in targets)
    compared = 0

    def counted(done: int, _: int) -> None:
        if progress is not None:
            progress(compared + done, total)

    for target in targets:
        report = _audit(target, store, counted, intake=intake, config=config, data_dir=data_dir)
        compared += report.compared
        if not report.identical:
            return dataclasses.replace(report, compared=compared)
    return AuditReport(submission_id, compared=compared)


def _audit(
    target: _Target,
    store: ArtifactStore,
    progress: Callable[[int, int], None],
    *,
    intake: IntakeSettings,
    config: SandboxSettings,
    data_dir: Path,
) -> AuditReport:
    recorded = target.manifest
    try:
        suite = load_suite(target.suite_dir)
        kind = sandbox.check_service_kind(None, config)
    except ArenaError as exc:
        raise Conflict(f"cannot audit submission {target.submission_id} here: {exc}") from exc
    with tempfile.TemporaryDirectory(prefix="arena-audit-") as tmp:
        scratch = Path(tmp)
        scratch.chmod(0o755)  # the sandbox user enters the prepared submission
        upload = store.fetch(target.upload_key, scratch / "upload.zip")
        model = (
            store.fetch(target.model_key, scratch / "model.tar.gz") if target.model_key else None
        )
        here = environment(kind.value, config.agent_image)
        current = manifest_of(
            suite,
            [EpisodeRun(e.scenario_id, e.episode, _seed(suite, e), here) for e in target.episodes],
            submission=file_sha256(upload),
            model=file_sha256(model) if model is not None else None,
            episodes_per_scenario=recorded.episodes_per_scenario,
            profile=recorded.profile,
            profile_version=recorded.profile_version,
        )
        refused = differences(recorded, current)
        if refused:
            return AuditReport(
                target.submission_id, refused=tuple(target.label + r for r in refused)
            )
        return _rerun(
            target,
            suite,
            kind,
            store,
            scratch,
            upload,
            model,
            progress,
            intake=intake,
            config=config,
            data_dir=data_dir,
        )


def _rerun(
    target: _Target,
    suite: Suite,
    kind: SandboxKind,
    store: ArtifactStore,
    scratch: Path,
    upload: Path,
    model: Path | None,
    progress: Callable[[int, int], None],
    *,
    intake: IntakeSettings,
    config: SandboxSettings,
    data_dir: Path,
) -> AuditReport:
    # Checked in the sandbox, as a worker does: nothing of the team's is parsed on this host.
    submission = validate(upload, scratch / "prepared", intake, config, data_dir, kind=kind)
    if model is not None:
        submission = dataclasses.replace(
            submission, model_dir=unpack_model(model, scratch / "model")
        )
    try:
        return _rerun_episodes(
            target,
            suite,
            kind,
            store,
            scratch,
            submission,
            progress,
            config=config,
            data_dir=data_dir,
        )
    finally:
        # Its warm agents bind the scratch folder, which goes when the audit ends: a later
        # audit of the same zip must not find them idle.
        warm_agents().close(submission.sha256)


def _rerun_episodes(
    target: _Target,
    suite: Suite,
    kind: SandboxKind,
    store: ArtifactStore,
    scratch: Path,
    submission,
    progress: Callable[[int, int], None],
    *,
    config: SandboxSettings,
    data_dir: Path,
) -> AuditReport:
    for done, stored in enumerate(target.episodes, start=1):
        outcome = run_scenario(
            submission,
            suite.scenario_dir(stored.scenario_id),
            scratch / "records",
            config=config,
            data_dir=data_dir,
            sandbox=kind,
            episode=stored.episode,
            limits=target.limits,
        )
        name = Episode(stored.scenario_id, stored.episode).name
        difference = _compare(stored, outcome, store, scratch / "stored" / f"{name}.npz")
        progress(done, len(target.episodes))
        if difference is not None:
            return AuditReport(
                target.submission_id,
                compared=done,
                difference=f"{target.label}{name}: {difference}",
            )
    return AuditReport(target.submission_id, compared=len(target.episodes))


def _compare(
    stored: _Stored, outcome: ScenarioOutcome, store: ArtifactStore, scratch: Path
) -> str | None:
    """What differs between a stored episode and its re-run, or None."""
    if str(outcome.status) != str(stored.status):
        return f"status {stored.status} -> {outcome.status}"
    agents = [agent.model_dump(mode="json") for agent in outcome.agents]
    if agents != stored.agents:
        return f"agent outcomes {stored.agents} -> {agents}"
    if stored.record_key is None or outcome.record_path is None:
        if (stored.record_key is None) != (outcome.record_path is None):
            return "one run wrote a record, the other did not"
        return None
    try:
        before = store.fetch(stored.record_key, scratch)
    except MissingArtifact:
        return f"the stored record {stored.record_key} is missing"
    if before.read_bytes() == outcome.record_path.read_bytes():
        return None
    return "record " + _first_difference(before, outcome.record_path)


def _first_difference(before: Path, after: Path) -> str:
    with np.load(before, allow_pickle=False) as a, np.load(after, allow_pickle=False) as b:
        for key in sorted(set(a.files) | set(b.files)):
            if key not in a.files or key not in b.files:
                return f"array {key!r} only in the {'re-run' if key in b.files else 'stored'} one"
            x, y = a[key], b[key]
            if x.shape != y.shape:
                return f"array {key!r} shape {x.shape} -> {y.shape}"
            differ = np.flatnonzero(~((x == y) | (_nan(x) & _nan(y))).reshape(-1))
            if differ.size:
                index = np.unravel_index(differ[0], x.shape)
                return f"array {key!r} at {tuple(map(int, index))}: {x[index]!r} -> {y[index]!r}"
    return "bytes differ (same arrays: the file's layout changed)"


def _nan(values: np.ndarray) -> np.ndarray:
    return (
        np.isnan(values)
        if np.issubdtype(values.dtype, np.floating)
        else np.zeros(values.shape, bool)
    )


def _seed(suite: Suite, stored: _Stored) -> int:
    entry = load_scenario(suite.scenario_dir(stored.scenario_id))
    return traffic_seed(stored.scenario_id, entry.seed, stored.episode)


def sample(db: Database, count: int, rng: random.Random | None = None) -> list[int]:
    """``count`` submissions drawn at random from every leaderboard (all phases and tracks)."""
    with db.read_session() as session:
        entries = sorted(
            {
                entry.submission_id
                for phase in session.scalars(select(Phase.name))
                for track in Track
                for entry in compute(session, track, phase).entries
            }
        )
    return sorted((rng or random.Random()).sample(entries, min(count, len(entries))))
