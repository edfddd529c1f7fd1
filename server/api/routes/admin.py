"""/admin: organiser actions over HTTP (the same service functions as `arena admin`)."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Body, Query, Response
from starlette.concurrency import run_in_threadpool

from server.api.contract import errors
from server.api.deps import (
    AdminDep,
    DatabaseDep,
    QueueDep,
    RowId,
    ScenarioId,
    SessionDep,
    SettingsDep,
)
from server.core.artifacts import artifact_store
from server.schemas import SubmissionSummary
from server.services import admin, replays, submissions

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
    settings: SettingsDep,
    db: DatabaseDep,
) -> dict:
    """Any episode of any submission, hidden phases included."""
    submission = submissions.get_submission(session, submission_id)
    return replays.submission_replay(session, settings, db, submission, scenario_id, organiser=True)


@router.post("/submissions/{submission_id}/disqualify", response_model=SubmissionSummary)
def disqualify(
    submission_id: SubmissionId,
    db: DatabaseDep,
    queue: QueueDep,
    reason: Annotated[str, Body(embed=True)] = "",
) -> SubmissionSummary:
    submissions.disqualify(db, queue, submission_id, reason)
    with db.read_session() as session:
        return submissions.summary(session, submissions.get_submission(session, submission_id))


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
    submission_id: SubmissionId, db: DatabaseDep, settings: SettingsDep, queue: QueueDep
) -> dict[str, int]:
    return {"attempt": admin.retrain(db, settings, queue, submission_id)}


@router.get(
    "/submissions/{submission_id}/model",
    response_class=Response,
    responses={200: {"content": {"application/gzip": {}}}},
)
def trained_model(submission_id: SubmissionId, db: DatabaseDep, settings: SettingsDep) -> Response:
    """The trained output of an offline submission, for audit: the ``.tar.gz`` whose sha256 the
    service stored (also in the ``X-Model-Sha256`` header)."""
    model = admin.trained_model(db, submission_id)
    return Response(
        artifact_store(settings, db).read(model.key),
        media_type="application/gzip",
        headers={
            "Content-Disposition": f'attachment; filename="{model.file_name}"',
            "X-Model-Sha256": model.sha256,
        },
    )


@router.post("/submissions/{submission_id}/rescore")
async def rescore(
    submission_id: SubmissionId, db: DatabaseDep, profile: str | None = None
) -> dict[str, dict[str, float]]:
    runs = admin.rescore_targets(db, submission_id)
    return {
        str(run_id): await run_in_threadpool(admin.rescore_run, db, run_id, profile)
        for run_id in runs
    }
