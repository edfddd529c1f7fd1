"""/admin: organiser actions over HTTP (the same service functions as `arena admin`)."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Body, Query, Response
from starlette.concurrency import run_in_threadpool

from evaluator.compare import comparison_document
from server.api.contract import errors
from server.api.deps import (
    MAX_ROW_ID,
    AdminDep,
    DatabaseDep,
    EvaluationDep,
    QueueDep,
    RowId,
    ScenarioId,
    ServiceDep,
    SessionDep,
    SettingsDep,
    StoreDep,
)
from server.schemas import SubmissionSummary
from server.services import admin, replays, submissions
from server.services.training_curves import training_svg as training_curves_svg

router = APIRouter(
    prefix="/admin",
    tags=["admin"],
    dependencies=[AdminDep],
    responses=errors(400, 401, 403, 404, 409, 422),
)
SubmissionId = RowId


@router.get("/submissions", response_model=list[SubmissionSummary])
def all_submissions(
    session: SessionDep, limit: Annotated[int, Query(ge=1, le=1000)] = 100
) -> list[SubmissionSummary]:
    return submissions.list_submissions(session, limit=limit)


@router.get("/submissions/{submission_id}/replays/{scenario_id}")
def replay(
    submission_id: SubmissionId,
    scenario_id: ScenarioId,
    session: SessionDep,
    store: StoreDep,
) -> dict:
    """Any episode of any submission, hidden phases included."""
    submission = submissions.get_submission(session, submission_id)
    return replays.submission_replay(session, store, submission, scenario_id, organiser=True)


@router.get(
    "/submissions/{submission_id}/training.svg",
    response_class=Response,
    responses={200: {"content": {"image/svg+xml": {}}}},
)
def training_curves(submission_id: SubmissionId, session: SessionDep, store: StoreDep) -> Response:
    """The training curves each seed's train.py logged, hidden phases included."""
    submission = submissions.get_submission(session, submission_id)
    return Response(
        training_curves_svg(session, store, submission, organiser=True),
        media_type="image/svg+xml",
    )


@router.post("/submissions/{submission_id}/disqualify", response_model=SubmissionSummary)
def disqualify(
    submission_id: SubmissionId,
    db: DatabaseDep,
    queue: QueueDep,
    reason: Annotated[str, Body(embed=True, min_length=1, max_length=2000)],
) -> SubmissionSummary:
    """Take a submission off the leaderboard for good; ``reason`` is shown to its team."""
    submissions.disqualify(db, queue, submission_id, reason)
    with db.read_session() as session:
        return submissions.summary(session, submissions.get_submission(session, submission_id))


@router.get("/compare")
def compare(
    a: Annotated[int, Query(ge=1, le=MAX_ROW_ID)],
    b: Annotated[int, Query(ge=1, le=MAX_ROW_ID)],
    db: DatabaseDep,
) -> dict[str, Any]:
    """Two submissions side by side, as ``arena admin compare A B --json`` prints them."""
    return comparison_document(*(admin.comparison_side(db, sid) for sid in (a, b)))


@router.post("/submissions/{submission_id}/requeue")
def requeue(
    submission_id: SubmissionId, db: DatabaseDep, settings: SettingsDep, queue: QueueDep
) -> dict[str, str]:
    return {"result": admin.requeue(db, settings, queue, submission_id)}


@router.post("/submissions/{submission_id}/rerun")
def rerun(
    submission_id: SubmissionId, db: DatabaseDep, settings: SettingsDep, queue: QueueDep
) -> dict[str, int]:
    return {"attempt": admin.rerun(db, settings, queue, submission_id)}


@router.post("/submissions/{submission_id}/retrain")
def retrain(
    submission_id: SubmissionId, db: DatabaseDep, service: ServiceDep, queue: QueueDep
) -> dict[str, int]:
    return {"attempt": admin.retrain(db, service, queue, submission_id)}


@router.get(
    "/submissions/{submission_id}/model",
    response_class=Response,
    responses={200: {"content": {"application/gzip": {}}}},
)
def trained_model(
    submission_id: SubmissionId,
    db: DatabaseDep,
    store: StoreDep,
    seed: Annotated[int | None, Query(ge=0, lt=16)] = None,
) -> Response:
    """The trained output of an offline submission, for audit: the ``.tar.gz`` whose sha256 the
    service stored (also in the ``X-Model-Sha256`` header); ``seed`` picks one seed's model when
    the phase trains several (required then)."""
    model = admin.trained_model(db, submission_id, seed)
    return Response(
        store.read(model.key),
        media_type="application/gzip",
        headers={
            "Content-Disposition": f'attachment; filename="{model.file_name}"',
            "X-Model-Sha256": model.sha256,
        },
    )


@router.post("/submissions/{submission_id}/rescore")
async def rescore(
    submission_id: SubmissionId,
    db: DatabaseDep,
    settings: SettingsDep,
    evaluation: EvaluationDep,
    store: StoreDep,
) -> dict[str, dict[str, float]]:
    """Re-score the submission's scored attempts with its phase's profile; keyed by attempt.
    (A phase's profile changes with `arena admin rescore --phase NAME --profile P`, which
    re-scores the whole phase: one submission is never ranked by other formulas.)"""
    targets = admin.rescore_targets(db, settings, submission_id=submission_id)
    scored = {}
    for target in targets:
        _, metrics = await run_in_threadpool(
            admin.rescore_run, db, evaluation, store, target.run_id
        )
        scored[str(target.attempt)] = metrics
    return scored
