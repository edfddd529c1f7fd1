"""Small builders of service test data."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

from sqlalchemy import select

from arena.config import Settings
from server.core.db import Database
from server.models import Phase, Submission, Visibility, utcnow
from server.processes import EXAMPLES, bearer  # noqa: F401  (bearer: the tests take it from here)
from server.sample_data import METRICS, seed_scored  # noqa: F401  (the tests take it here)
from server.services import evaluation, teams
from server.status import SubmissionStatus
from server.tracks import Track
from tests.settings import evaluate_args


def scenario_ids(plan) -> tuple[str, ...]:
    """The scenarios of a plan of one episode per scenario."""
    assert all(episode.index == 0 for episode in plan.episodes)
    return tuple(episode.scenario_id for episode in plan.episodes)


def write_suite(root: Path, families: dict[str, int]) -> Path:
    """A suite folder with a manifest and empty scenario folders (enough for the bookkeeping;
    the end-to-end tests use real scenarios)."""
    entries = []
    for family, count in families.items():
        for k in range(count):
            sid = f"hidden_{family}_{k}"
            (root / sid).mkdir(parents=True)
            # A content hash like a real build's: it never spells the scenario's id.
            digest = hashlib.sha256(sid.encode()).hexdigest()
            entries.append({"id": sid, "family": family, "hash": digest})
    (root / "manifest.json").write_text(json.dumps({"suite": "hidden", "scenarios": entries}))
    return root


def make_team(db: Database, name: str) -> tuple[int, str]:
    with db.session() as session:
        team, token = teams.create_team(session, name)
        return team.id, token


def pack_example(name: str, out_dir: Path) -> Path:
    from submissions.intake import pack_folder

    return pack_folder(EXAMPLES / name, out_dir / f"{name}.zip")


def queued_submission(
    db: Database, team_id: int, track: Track = Track.freestyle, phase: str = "final"
) -> int:
    with db.session() as session:
        submission = Submission(
            team_id=team_id,
            phase=phase,
            track=track,
            method_name="m",
            file_sha256="0" * 64,
            file_size=1,
            upload_key="submissions/none/upload.zip",
            status=SubmissionStatus.queued,
            queued_at=utcnow(),
        )
        session.add(submission)
        session.flush()
        return submission.id


def agent(reached_goal: bool, done_step: int = 100, reason: str | None = None) -> dict:
    """An agent summary that drove no recorded step (scored without a record)."""
    return {
        "id": "Agent_0",
        "reached_goal": reached_goal,
        "reason": reason or ("reached_goal" if reached_goal else "collision"),
        "steps": 0,
        "done_step": done_step,
    }


def claim_episode(session, settings: Settings, plan, episode):
    """Worker "w1"'s claim of one episode of ``plan`` (None: not claimable)."""
    return evaluation.claim_scenario(
        session,
        settings.service,
        settings.sandbox,
        plan.run_id,
        episode.scenario_id,
        "w1",
        episode.index,
    )


def report_episode(
    db: Database, settings: Settings, plan, episode, *, reached_goal: bool, agent_cpu_s: float = 0.0
) -> bool | None:
    """One episode of ``plan`` claimed and reported done as a worker does (no record), its agent
    reaching the goal or colliding; None if it could not be claimed, else whether it finished
    the run (the worker then sends the aggregation)."""
    from arena.outcome import AgentOutcome, ScenarioStatus
    from evaluator.runner import ScenarioOutcome

    with db.session() as session:
        job = claim_episode(session, settings, plan, episode)
    if job is None:
        return None
    outcome = ScenarioOutcome(
        scenario_id=episode.scenario_id,
        status=ScenarioStatus.done,
        steps=0,
        agents=(AgentOutcome(**agent(reached_goal)),),
        record_path=None,
        episode=episode.index,
        agent_cpu_s=agent_cpu_s,
    )
    with db.session() as session:
        return evaluation.record_scenario(session, job, "w1", outcome, "", record_key=None)


def default_phases() -> list[Phase]:
    """The phases migration 0003 creates: validation on the public suite, the hidden final."""
    return [
        Phase(name="validation", suite="public", visibility=Visibility.full),
        Phase(name="final", suite="hidden", visibility=Visibility.hidden),
    ]


def evaluate_failing_everywhere(
    db: Database,
    settings,
    submission_id: int,
    *,
    log: str,
    error: str | None = None,
    episodes: int | None = None,
) -> None:
    """Run the submission through the service's bookkeeping as a worker would: every scenario
    (or the first ``episodes``: the run stays under way) claimed, reported done with its agent
    colliding (no record) and ``log`` as its output, then the run aggregated."""
    from arena.outcome import AgentOutcome, ScenarioStatus
    from evaluator.runner import ScenarioOutcome
    from server.core.artifacts import DatabaseStore

    with db.session() as session:
        plan = evaluation.start_evaluation(session, settings, submission_id)
    for scenario_id in scenario_ids(plan)[:episodes]:
        with db.session() as session:
            job = evaluation.claim_scenario(
                session, settings.service, settings.sandbox, plan.run_id, scenario_id, "w1"
            )
        outcome = ScenarioOutcome(
            scenario_id=scenario_id,
            status=ScenarioStatus.done,
            steps=0,
            agents=(AgentOutcome(**agent(False)),),
            record_path=None,
            error=error,
        )
        with db.session() as session:
            evaluation.record_scenario(session, job, "w1", outcome, log)
    if episodes is not None and episodes < len(plan.episodes):
        return
    with db.session() as session:
        assert evaluation.finish_run(session, DatabaseStore(db), plan.run_id) is not None


def validate_uploads(db: Database, settings: Settings, worker: str = "test-worker") -> list[int]:
    """Run the validation job of every upload ``validating``, as a worker does (the intake in
    the service's sandbox, the verdict recorded through the fence); the ids validated."""
    from evaluator.sandbox import check_service_kind
    from server.core.artifacts import artifact_store
    from server.core.queue import TaskQueue
    from server.services import validation
    from server.status import SubmissionStatus
    from server.worker.validations import judge, record

    with db.read_session() as session:
        pending = list(
            session.scalars(
                select(Submission.id).where(Submission.status == SubmissionStatus.validating)
            )
        )
    store = artifact_store(settings.storage, db)
    kind = check_service_kind(None, settings.sandbox)
    queue = TaskQueue(settings)
    try:
        for _ in pending:
            with db.session() as session:
                claim = validation.claim(session, settings.service, settings.intake, worker)
            assert claim is not None
            scratch = settings.storage.resolved_data_dir / "scratch" / worker
            verdict = judge(
                claim, store, kind, {"arena.test": worker}, scratch, **evaluate_args(settings)
            )
            record(
                claim,
                worker,
                verdict,
                db,
                store,
                queue,
                intake=settings.intake,
                data_dir=settings.storage.resolved_data_dir,
            )
    finally:
        queue.close()
    return pending
