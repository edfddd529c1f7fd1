"""/scenarios/public: the public suite participants evaluate on locally, and its expert drives to
watch."""

from __future__ import annotations

from fastapi import APIRouter, Request, Response
from starlette.concurrency import run_in_threadpool

from server.api.contract import errors
from server.api.deps import DatabaseDep, ScenarioId, SettingsDep
from server.schemas import PublicScenario
from server.services import replays, scenarios

router = APIRouter(tags=["scenarios"])
# The public replays change only with the public suite (their key is its content hash).
REPLAY_MAX_AGE_S = 3600


@router.get("/scenarios/public", response_model=list[PublicScenario])
def public_scenarios(settings: SettingsDep) -> list[PublicScenario]:
    return [
        PublicScenario.model_validate(e.model_dump()) for e in scenarios.public_scenarios(settings)
    ]


@router.get(
    "/scenarios/public/{scenario_id}/replay",
    response_class=Response,
    responses={200: {"content": {"application/json": {}}}, **errors(404, 422)},
)
async def public_replay(
    request: Request, scenario_id: ScenarioId, settings: SettingsDep, db: DatabaseDep
) -> Response:
    """The expert's drive through a public scenario, to watch (the replay page's data). The
    first request simulates it (a few seconds); later ones are served from memory, with an
    ``ETag`` (``If-None-Match`` gets 304) and a cache lifetime."""
    document = await run_in_threadpool(replays.public_replay, settings, db, scenario_id)
    headers = {"ETag": document.etag, "Cache-Control": f"public, max-age={REPLAY_MAX_AGE_S}"}
    if request.headers.get("if-none-match") == document.etag:
        return Response(status_code=304, headers=headers)
    return Response(document.body, media_type="application/json", headers=headers)
