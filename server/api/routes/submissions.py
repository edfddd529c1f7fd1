"""/submissions: upload, list, detail, logs, cancel."""

from __future__ import annotations

from fastapi import APIRouter, Request, Response, status
from starlette.concurrency import run_in_threadpool

from server.api.contract import UPLOAD_FORM, errors
from server.api.deps import (
    CurrentTeam,
    DatabaseDep,
    LeaderboardDep,
    OwnedSubmission,
    QueueDep,
    SandboxDep,
    ScenarioId,
    ServiceDep,
    SessionDep,
    SettingsDep,
    StoreDep,
)
from server.api.upload import receive_form
from server.schemas import SubmissionDetail, SubmissionLogs, SubmissionSummary
from server.services import (
    downloads,
    replays,
    result_charts,
    standing,
    submissions,
    training_curves,
    validation,
)
from server.services.errors import InvalidUpload
from server.services.phases import DEFAULT_PHASE
from server.tracks import Track

router = APIRouter(prefix="/submissions", tags=["submissions"], responses=errors(401, 404, 422))


@router.post(
    "",
    status_code=status.HTTP_202_ACCEPTED,
    response_model=SubmissionDetail,
    responses={
        202: {
            "description": "Received and stored; validating (poll Location until it is "
            "queued or rejected)",
            "headers": {
                "Location": {
                    "description": "The submission's URL",
                    "schema": {"type": "string"},
                }
            },
        },
        **errors(403, 409, 413, 429),
    },
    openapi_extra=UPLOAD_FORM,
)
async def create_submission(
    request: Request,
    response: Response,
    team: CurrentTeam,
    db: DatabaseDep,
    settings: SettingsDep,
    queue: QueueDep,
) -> SubmissionDetail:
    """Multipart form: ``file`` (the zip), ``phase`` (default ``final``), ``track``
    (freestyle|offline), ``method_name``, ``description``. The request only receives, bounds and
    queues: it answers ``202`` with status ``validating`` once the zip is stored, and a job
    validates it in the sandbox; poll ``Location`` until it is ``queued`` (or ``rejected``, with
    the reason in ``status_reason``). A zip whose size or directory breaks a rule gets 413/422
    at once; a team has one upload validating at a time (409)."""
    with db.read_session() as session:
        validation.check_not_busy(session, team.id)
    form = await receive_form(
        request, settings.storage.resolved_data_dir / "uploads", settings.intake.max_zip_bytes
    )
    try:
        try:
            track = Track(form.fields.get("track", Track.freestyle))
        except ValueError:
            raise InvalidUpload("track: must be 'freestyle' or 'offline'") from None
        new = submissions.NewSubmission(
            track=track,
            method_name=form.fields.get("method_name", ""),
            description=form.fields.get("description", ""),
            phase=form.fields.get("phase") or DEFAULT_PHASE,
        )
        created = await run_in_threadpool(
            submissions.accept_upload,
            db,
            settings,
            queue,
            team.id,
            new,
            form.file_path,
            form.sha256,
        )
    finally:
        form.file_path.unlink(missing_ok=True)
    # Relative (or under the configured base URL): never built from the request's Host header.
    response.headers["Location"] = (
        f"{settings.service.public_base_url}/api/v1/submissions/{created.id}"
    )
    with db.read_session() as session:
        submission = submissions.get_submission(session, created.id)
        return standing.team_view(session, settings.service, settings.sandbox, submission)


@router.get("", response_model=list[SubmissionSummary])
def list_submissions(session: SessionDep, team: CurrentTeam) -> list[SubmissionSummary]:
    """The caller's team's submissions, newest first."""
    return submissions.list_submissions(session, team.id)


@router.get("/{submission_id}", response_model=SubmissionDetail)
def get_submission(
    session: SessionDep, service: ServiceDep, sandbox: SandboxDep, submission: OwnedSubmission
) -> SubmissionDetail:
    """Status, timings, scores, the phase (dates, what it hides) and where the team stands
    (rank, uploads left today)."""
    return standing.team_view(session, service, sandbox, submission)


@router.get("/{submission_id}/logs", response_model=SubmissionLogs, responses=errors(403))
def get_logs(session: SessionDep, submission: OwnedSubmission) -> SubmissionLogs:
    """The agent's stdout/stderr tail per scenario, in a phase of full visibility (validation);
    403 in a hidden phase, whose agent output goes to the organisers only."""
    return submissions.logs(session, submission)


@router.get(
    "/{submission_id}/results.svg",
    response_class=Response,
    responses={200: {"content": {"image/svg+xml": {}}}, **errors(409)},
)
def get_results_chart(
    session: SessionDep, cache: LeaderboardDep, submission: OwnedSubmission
) -> Response:
    """The submission's results drawn (the submission page shows it): completion with its 95%
    interval as a bar, and the four metrics per family beside the leaderboard's median; 409
    until it is scored."""
    return Response(
        result_charts.results_svg(session, cache, submission), media_type="image/svg+xml"
    )


@router.get(
    "/{submission_id}/training.svg",
    response_class=Response,
    responses={200: {"content": {"image/svg+xml": {}}}, **errors(403)},
)
def get_training_curves(
    session: SessionDep, store: StoreDep, submission: OwnedSubmission
) -> Response:
    """The training curves each seed's train.py logged (docs/training.md), live while it
    trains; in a phase whose results the team sees in full (403 in a hidden one)."""
    return Response(
        training_curves.training_svg(session, store, submission), media_type="image/svg+xml"
    )


@router.get("/{submission_id}/replays/{scenario_id}", responses=errors(403))
def get_replay(
    session: SessionDep,
    store: StoreDep,
    submission: OwnedSubmission,
    scenario_id: ScenarioId,
) -> dict:
    """One episode to watch (the replay page's data: map, every vehicle's pose per step, the
    agents' speed and events), in a phase of full visibility; 403 in a hidden phase."""
    return replays.submission_replay(session, store, submission, scenario_id)


@router.get(
    "/{submission_id}/download",
    response_class=Response,
    responses={200: {"content": {"application/zip": {}}}},
)
def download_submission(
    session: SessionDep,
    service: ServiceDep,
    sandbox: SandboxDep,
    store: StoreDep,
    submission: OwnedSubmission,
) -> Response:
    """A zip of what the team may see: ``submission.json`` (status, scores, failure counts),
    the zip the team uploaded (``upload/agent.zip``), and in a phase of full visibility
    ``logs.json`` and ``logs/<family>-<k>.txt`` per finished scenario."""
    return Response(
        downloads.submission_zip(session, service, sandbox, store, submission),
        media_type="application/zip",
        headers={
            "Content-Disposition": f'attachment; filename="{downloads.download_name(submission)}"'
        },
    )


@router.post("/{submission_id}/cancel", response_model=SubmissionSummary, responses=errors(409))
def cancel_submission(
    submission: OwnedSubmission, db: DatabaseDep, queue: QueueDep
) -> SubmissionSummary:
    submissions.cancel(db, queue, submission.id)
    with db.read_session() as session:
        return submissions.summary(session, submissions.get_submission(session, submission.id))
