"""Integrity of what the service stores and answers, on SQLite and PostgreSQL: any byte of agent
output records, form fields are bounded as a whole, ids out of the database's range are refused."""

from __future__ import annotations

import pytest

from arena.suite import load_suite
from tests.server.builders import bearer, evaluate_failing_everywhere, make_team, queued_submission

NASTY = "before\x00after \ud800 lone surrogate \x01\x7f end"


def upload(client, token, payload: bytes, **fields: str):
    data = {"track": "freestyle", "method_name": "m", "description": "d", **fields}
    return client.post(
        "/api/v1/submissions",
        headers=bearer(token),
        data=data,
        files={"file": ("agent.zip", payload, "application/zip")},
    )


def test_agent_output_with_any_byte_records_and_reads_back(client, db, settings):
    """One NUL in agent output failed the recording on PostgreSQL: re-simulated three times,
    then the submission failed, uncounted by the quota."""
    team, token = make_team(db, "alpha")
    # The validation phase, where the team reads its agent's output back.
    submission_id = queued_submission(db, team, phase="validation")
    evaluate_failing_everywhere(db, settings, submission_id, log=NASTY * 100, error=NASTY)
    response = client.get(f"/api/v1/submissions/{submission_id}/logs", headers=bearer(token))
    assert response.status_code == 200
    tails = [s["log_tail"] for s in response.json()["scenarios"]]
    assert len(tails) == len(load_suite(settings.suites.public_suite_dir).scenarios)
    for tail in tails:
        assert "\x00" not in tail and "before\ufffdafter" in tail and "\x01\x7f end" in tail


@pytest.mark.parametrize("field", ["method_name", "description"])
def test_a_nul_in_a_text_field_is_422_not_500(client, db, field):
    _, token = make_team(db, "alpha")
    response = upload(client, token, b"PK-not-read", **{field: "evil\x00name"})
    assert response.status_code == 422, response.text
    assert field in response.json()["detail"] and "control character" in response.json()["detail"]


def test_form_fields_are_capped_in_number_and_in_total(client, db, settings):
    _, token = make_team(db, "alpha")
    many = {f"f{i}": "x" for i in range(200)}
    response = upload(client, token, b"zip", **many)
    assert response.status_code == 413 and "fields" in response.json()["detail"]
    big = {f"f{i}": "x" * 60_000 for i in range(6)}  # each under 64 KiB, together 360 KB
    response = upload(client, token, b"zip", **big)
    assert response.status_code == 413 and "in total" in response.json()["detail"]
    uploads = settings.storage.resolved_data_dir / "uploads"
    assert not uploads.exists() or not any(uploads.iterdir())


OUT_OF_RANGE = [2**31, 2**63, 2**64, 10**30]


@pytest.mark.parametrize("submission_id", OUT_OF_RANGE)
def test_ids_beyond_the_databases_range_are_refused_not_500(client, db, submission_id):
    _, token = make_team(db, "alpha")
    team_routes = [
        ("get", f"/api/v1/submissions/{submission_id}"),
        ("get", f"/api/v1/submissions/{submission_id}/logs"),
        ("post", f"/api/v1/submissions/{submission_id}/cancel"),
        ("get", f"/submissions/{submission_id}"),
    ]
    for method, path in team_routes:
        response = client.request(method, path, headers=bearer(token))
        assert response.status_code in (404, 422), (path, response.status_code)
    admin = bearer(client.app.state.settings.service.admin_token)
    for action in ("disqualify", "requeue", "rerun", "rescore"):
        path = f"/api/v1/admin/submissions/{submission_id}/{action}"
        response = client.post(path, headers=admin)
        assert response.status_code in (404, 422), (path, response.status_code)


@pytest.mark.parametrize("limit", [-1, 0, 2**31, 2**63])
def test_admin_list_limit_out_of_range_is_422(client, db, limit):
    admin = bearer(client.app.state.settings.service.admin_token)
    response = client.get(f"/api/v1/admin/submissions?limit={limit}", headers=admin)
    assert response.status_code == 422


def test_the_largest_valid_id_is_a_plain_404(client, db):
    _, token = make_team(db, "alpha")
    response = client.get(f"/api/v1/submissions/{2**31 - 1}", headers=bearer(token))
    assert response.status_code == 404
