"""/scenarios/public: the public suite participants evaluate on locally."""

from __future__ import annotations

from fastapi import APIRouter

from server.api.deps import SettingsDep
from server.schemas import PublicScenario
from server.services import scenarios

router = APIRouter(tags=["scenarios"])


@router.get("/scenarios/public", response_model=list[PublicScenario])
def public_scenarios(settings: SettingsDep) -> list[PublicScenario]:
    return [
        PublicScenario.model_validate(e.model_dump()) for e in scenarios.public_scenarios(settings)
    ]
