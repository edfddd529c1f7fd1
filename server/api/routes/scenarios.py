"""/scenarios/public: the public suite participants evaluate on locally, and its expert drives to
watch."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Path, Request, Response
from fastapi.responses import FileResponse
from starlette.concurrency import run_in_threadpool

from server.api.contract import errors
from server.api.deps import ScenarioId, SessionDep, StorageDep, StoreDep, SuitesDep
from server.schemas import PublicScenario
from server.services import release, replays, scenarios

router = APIRouter(tags=["scenarios"])
# The public replays change only with the public suite (their key is its content hash).
REPLAY_MAX_AGE_S = 3600


@router.get("/scenarios/public", response_model=list[PublicScenario])
def public_scenarios(suites: SuitesDep) -> list[PublicScenario]:
    return [
        PublicScenario.model_validate(e.model_dump()) for e in scenarios.public_scenarios(suites)
    ]


@router.get(
    "/scenarios/public/{scenario_id}/replay",
    response_class=Response,
    responses={200: {"content": {"application/json": {}}}, **errors(404, 422)},
)
async def public_replay(
    request: Request, scenario_id: ScenarioId, suites: SuitesDep, store: StoreDep
) -> Response:
    """The expert's drive through a public scenario, to watch (the replay page's data). The
    first request simulates it (a few seconds); later ones are served from memory, with an
    ``ETag`` (``If-None-Match`` gets 304) and a cache lifetime."""
    document = await run_in_threadpool(replays.public_replay, suites, store, scenario_id)
    headers = {"ETag": document.etag, "Cache-Control": f"public, max-age={REPLAY_MAX_AGE_S}"}
    if request.headers.get("if-none-match") == document.etag:
        return Response(status_code=304, headers=headers)
    return Response(document.body, media_type="application/json", headers=headers)


@router.get(
    "/scenarios/released/{phase}.zip",
    response_class=FileResponse,
    responses={200: {"content": {"application/zip": {}}}, **errors(403, 404, 422)},
)
def released_suite(
    session: SessionDep,
    suites: SuitesDep,
    storage: StorageDep,
    phase: Annotated[str, Path(max_length=32, pattern=r"^[A-Za-z0-9_-]+$")],
) -> FileResponse:
    """The whole suite of a phase the organisers released after it closed (403 before)."""
    path = release.released_suite(session, suites, storage.resolved_data_dir, phase)
    return FileResponse(path, media_type="application/zip", filename=f"suite-{phase}.zip")
