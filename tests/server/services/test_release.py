"""Releasing a closed phase: refused while it is open; before the release nothing a team sees
changes, after it the suite downloads and each team sees its own hidden episodes."""

from __future__ import annotations

import io
import zipfile
from datetime import timedelta

import pytest

from server.models import utcnow
from server.services import phases, release
from server.services.errors import Conflict
from tests.server.builders import bearer, make_team, queued_submission
from tests.server.worker.test_evaluation_flow import run_everything, start


def close(db, settings, ends_in: timedelta) -> None:
    phases.set_phase(db, settings, "final", phases.PhaseChanges(ends_at=utcnow() + ends_in))


def test_an_open_phase_cannot_be_released(db, settings):
    with pytest.raises(Conflict, match="has no end date"):
        release.release_phase(db, "final")
    close(db, settings, timedelta(hours=1))
    with pytest.raises(Conflict, match="closes at"):
        release.release_phase(db, "final")


def test_after_the_release_the_suite_downloads_and_teams_see_their_episodes(client, db, settings):
    team, token = make_team(db, "alpha")
    sid = queued_submission(db, team)
    run_everything(db, settings, start(db, settings, sid))
    close(db, settings, -timedelta(minutes=1))
    auth = bearer(token)
    # Closed but not released: as hidden as ever.
    assert client.get("/api/v1/scenarios/released/final.zip").status_code == 403
    assert client.get(f"/api/v1/submissions/{sid}/logs", headers=auth).status_code == 403
    replay = f"/api/v1/submissions/{sid}/replays/hidden_cruise_0"
    assert client.get(replay, headers=auth).status_code == 403
    with zipfile.ZipFile(
        io.BytesIO(client.get(f"/api/v1/submissions/{sid}/download", headers=auth).content)
    ) as archive:
        assert archive.namelist() == ["submission.json"]

    released = release.release_phase(db, "final")
    assert release.release_phase(db, "final").released_at == released.released_at  # once
    suite = client.get("/api/v1/scenarios/released/final.zip")
    assert suite.status_code == 200
    with zipfile.ZipFile(io.BytesIO(suite.content)) as archive:
        names = archive.namelist()
    assert "manifest.json" in names
    assert client.get("/api/v1/scenarios/released/final.zip").content == suite.content
    logs = client.get(f"/api/v1/submissions/{sid}/logs", headers=auth)
    assert logs.status_code == 200
    shown = {entry["scenario_id"] for entry in logs.json()["scenarios"]}
    assert shown == {"hidden_cruise_0", "hidden_cruise_1", "hidden_merge_0"}
    # Watching is allowed now (this test's agents drove no step, so there is nothing to watch).
    assert "no recorded episode" in client.get(replay, headers=auth).json()["detail"]
    with zipfile.ZipFile(
        io.BytesIO(client.get(f"/api/v1/submissions/{sid}/download", headers=auth).content)
    ) as archive:
        assert "logs.json" in archive.namelist()
    assert client.get("/api/v1/scenarios/released/nope.zip").status_code == 404
