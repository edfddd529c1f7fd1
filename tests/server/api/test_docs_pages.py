"""The service's own docs: Swagger UI from local assets, the favicon, the participant guides and
the per-submission download (the browser tests cover rendering; these cover the HTTP contract)."""

from __future__ import annotations

import io
import json
import zipfile

from tests.server.builders import bearer, make_team, seed_scored


def test_docs_page_points_only_at_local_assets(client):
    page = client.get("/docs")
    assert page.status_code == 200
    assert "/docs-assets/swagger-ui-bundle.js" in page.text and "cdn" not in page.text.lower()
    assert client.get("/docs-assets/swagger-ui-bundle.js").status_code == 200
    assert client.get("/docs-assets/swagger-ui.css").status_code == 200
    icon = client.get("/favicon.ico")
    assert icon.status_code == 200 and icon.content[:4] == b"\x89PNG"


def test_guides_render_and_link_each_other(client):
    guide = client.get("/guide/agent-interface")
    assert guide.status_code == 200
    assert "<table>" in guide.text and "LaneWithContinuousSpeed" in guide.text
    assert 'href="/guide/submissions#why-an-episode-failed"' in guide.text
    assert client.get("/guide/submissions").status_code == 200
    assert client.get("/guide/scoring-secrets").status_code == 404


def test_download_holds_what_the_team_may_see_and_only_for_the_team(client, db):
    team, token = make_team(db, "alpha")
    _, other = make_team(db, "beta")
    sid = seed_scored(db, team, (0.5, 400.0, 0.25, 0.125), phase="validation")
    response = client.get(f"/api/v1/submissions/{sid}/download", headers=bearer(token))
    assert response.status_code == 200
    assert response.headers["content-type"] == "application/zip"
    assert f'filename="submission-{sid}.zip"' in response.headers["content-disposition"]
    with zipfile.ZipFile(io.BytesIO(response.content)) as archive:
        assert sorted(archive.namelist()) == ["logs.json", "submission.json"]
        detail = json.loads(archive.read("submission.json"))
    # In a hidden phase the download holds the scores and counts, nothing the agent wrote.
    hidden = seed_scored(db, team, (0.5, 400.0, 0.25, 0.125))
    response = client.get(f"/api/v1/submissions/{hidden}/download", headers=bearer(token))
    with zipfile.ZipFile(io.BytesIO(response.content)) as archive:
        assert archive.namelist() == ["submission.json"]
    assert detail["metrics"] == {
        "completion": 0.5,
        "time": 400.0,
        "humanness": 0.25,
        "rules": 0.125,
    }
    other_team = client.get(f"/api/v1/submissions/{sid}/download", headers=bearer(other))
    assert other_team.status_code in (403, 404)
    assert client.get(f"/api/v1/submissions/{sid}/download").status_code == 401
