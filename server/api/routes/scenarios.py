"""/scenarios/public: the public suite participants evaluate on locally."""

from __future__ import annotations

from fastapi import APIRouter

from server.api.deps import SettingsDep
from server.schemas import PublicScenario
from server.services.suites import load_suite, public_suite_dir

router = APIRouter(tags=["scenarios"])


@router.get("/scenarios/public", response_model=list[PublicScenario])
def public_scenarios(settings: SettingsDep) -> list[PublicScenario]:
    suite = load_suite(public_suite_dir(settings))
    return [PublicScenario.model_validate(entry) for entry in suite.manifest.scenarios]
