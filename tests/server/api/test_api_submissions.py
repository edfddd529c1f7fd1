"""POST/GET /submissions over HTTP with the real intake (in the service's sandbox), database and
broker: uploads received and validated, rejections, authentication, ownership, quotas and
cancel."""

from __future__ import annotations

import io
import zipfile

import pytest
from sqlalchemy import func, select

from server.models import Submission, utcnow
from server.services import evaluation
from server.services.submissions import quota_used
from server.status import SubmissionStatus
from server.tracks import Track
from tests.server.builders import bearer, make_team, pack_example, validate_uploads
from tests.settings import with_fields
from tests.submissions.zips import bad_crc_zip


def upload(client, token, payload: bytes, *, track="freestyle", method="keep lane", phase="final"):
    return client.post(
        "/api/v1/submissions",
        headers=bearer(token),
        data={"track": track, "method_name": method, "description": "test", "phase": phase},
        files={"file": ("agent.zip", payload, "application/zip")},
    )


def zip_bytes(entries: dict[str, bytes]) -> bytes:
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w") as archive:
        for name, data in entries.items():
            info = zipfile.ZipInfo(name)
            info.external_attr = 0o100644 << 16  # a regular file, as zip tools write it
            archive.writestr(info, data)
    return buffer.getvalue()


@pytest.fixture
def keep_lane_zip(tmp_path) -> bytes:
    return pack_example("keep_lane", tmp_path).read_bytes()


def count_submissions(db) -> int:
    with db.session() as session:
        return session.scalar(select(func.count()).select_from(Submission))


def submission(client, token, sid: int) -> dict:
    return client.get(f"/api/v1/submissions/{sid}", headers=bearer(token)).json()


def accepted(client, db, settings, token, payload: bytes, **options) -> dict:
    """Upload (202 validating), run the validation job, and return the submission as it then
    reads."""
    response = upload(client, token, payload, **options)
    assert response.status_code == 202, response.text
    assert response.json()["status"] == "validating"
    validate_uploads(db, settings)
    return submission(client, token, response.json()["id"])


@pytest.mark.slow  # the intake in the service's sandbox
def test_upload_is_received_validated_then_queued(client, db, settings, keep_lane_zip):
    _, token = make_team(db, "alpha")
    response = upload(client, token, keep_lane_zip)
    assert response.status_code == 202, response.text
    body = response.json()
    assert body["status"] == "validating"
    assert response.headers["location"] == f"/api/v1/submissions/{body['id']}"
    assert validate_uploads(db, settings) == [body["id"]]
    assert submission(client, token, body["id"])["status"] == "queued"
    assert body["team"] == "alpha"
    assert body["file_size"] == len(keep_lane_zip)
    assert body["progress"] == {"done": 0, "total": 0, "seeds": 1, "unit": "episodes"}
    listed = client.get("/api/v1/submissions", headers=bearer(token)).json()
    assert [item["id"] for item in listed] == [body["id"]]
    with db.session() as session:
        stored = session.get(Submission, body["id"])
        assert (settings.storage.resolved_data_dir / stored.upload_key).is_file()


@pytest.mark.parametrize(
    "payload,needle",
    [
        (b"this is not a zip", ""),
        (zip_bytes({"../evil.py": b"x = 1\n", "policy.py": b"class Policy: pass\n"}), "evil"),
        (zip_bytes({"policy.py": b"class Policy: pass\n", "a": b"", "a/b": b""}), "file-folder"),
        (zip_bytes({"policy.py": b"class Policy: pass\n", "n" * 300: b""}), "name-too-long"),
    ],
    ids=["not-a-zip", "zip-slip", "file-beside-folder", "300-character-name"],
)
def test_a_zip_whose_directory_breaks_a_rule_gets_422_at_once(client, db, payload, needle):
    _, token = make_team(db, "alpha")
    response = upload(client, token, payload)
    assert response.status_code == 422
    detail = response.json()["detail"]
    assert "[rule:" in detail and needle in detail
    assert count_submissions(db) == 0


@pytest.mark.parametrize(
    "payload,needle",
    [
        (zip_bytes({"agent.yaml": b"action_space: TargetPose\n"}), "policy.py"),
        (zip_bytes({"policy.py": b"class Policy(:\n"}), "policy.py"),
        (
            zip_bytes({"policy.py": b"x = " + b"1+" * 100_000 + b"1\nclass Policy: pass\n"}),
            "policy-too-deep",
        ),
        (bad_crc_zip({"policy.py": "class Policy: pass\n", "w.txt": "x" * 100}), "corrupt-entry"),
    ],
    ids=["no-policy", "syntax-error", "deep-expression", "bad-crc"],
)
@pytest.mark.slow  # the intake in the service's sandbox
def test_a_zip_whose_contents_break_a_rule_is_rejected_by_its_validation(
    client, db, settings, payload, needle
):
    """What needs the entries' bytes is judged by the validation job, in the sandbox: the team
    reads the same message a synchronous 422 gave, and the try is given back."""
    team_id, token = make_team(db, "alpha")
    body = accepted(client, db, settings, token, payload)
    assert body["status"] == "rejected"
    assert "[rule:" in body["status_reason"] and needle in body["status_reason"]
    with db.session() as session:
        upload_key = session.get(Submission, body["id"]).upload_key
    assert not (settings.storage.resolved_data_dir / upload_key).exists()
    with db.session() as session:
        assert quota_used(session, team_id, "final", Track.freestyle, utcnow()) == 0


def test_upload_without_file_or_with_a_bad_track_is_rejected(client, db, keep_lane_zip):
    _, token = make_team(db, "alpha")
    response = client.post(
        "/api/v1/submissions", headers=bearer(token), data={"method_name": "x"}, files={}
    )
    assert response.status_code == 422
    assert upload(client, token, keep_lane_zip, track="nascar").status_code == 422
    assert upload(client, token, keep_lane_zip, method="  ").status_code == 422
    assert count_submissions(db) == 0


def test_missing_or_unknown_token_is_401(client, db, keep_lane_zip):
    assert client.get("/api/v1/submissions").status_code == 401
    assert client.get("/api/v1/submissions", headers=bearer("arena_nope")).status_code == 401
    assert upload(client, "arena_nope", keep_lane_zip).status_code == 401


def test_rotated_token_stops_working(client, db):
    from server.services import teams

    _, old = make_team(db, "alpha")
    with db.session() as session:
        new = teams.rotate_token(session, teams.get_team(session, "alpha"))
    assert client.get("/api/v1/submissions", headers=bearer(old)).status_code == 401
    assert client.get("/api/v1/submissions", headers=bearer(new)).status_code == 200


def test_a_team_never_sees_another_teams_submission(client, db, keep_lane_zip):
    _, token_a = make_team(db, "alpha")
    _, token_b = make_team(db, "bravo")
    sid = upload(client, token_a, keep_lane_zip, phase="validation").json()["id"]
    for path in (f"/api/v1/submissions/{sid}", f"/api/v1/submissions/{sid}/logs"):
        assert client.get(path, headers=bearer(token_a)).status_code == 200
        response = client.get(path, headers=bearer(token_b))
        assert response.status_code == 404
        assert "alpha" not in response.text
    assert (
        client.post(f"/api/v1/submissions/{sid}/cancel", headers=bearer(token_b)).status_code == 404
    )
    assert client.get("/api/v1/submissions", headers=bearer(token_b)).json() == []


@pytest.mark.slow  # the intake in the service's sandbox
def test_daily_quota_per_team_and_track(client, db, settings, keep_lane_zip, tmp_path):
    _, token = make_team(db, "alpha")
    ids = [
        accepted(client, db, settings, token, keep_lane_zip)["id"]
        for _ in range(settings.service.daily_quota)
    ]
    response = upload(client, token, keep_lane_zip)
    assert response.status_code == 429
    assert "quota" in response.json()["detail"]
    # Another track has its own quota.
    offline_zip = pack_example("offline_bc", tmp_path).read_bytes()
    assert accepted(client, db, settings, token, offline_zip, track="offline")["status"] == "queued"
    # Cancelled before it started: does not count.
    assert (
        client.post(f"/api/v1/submissions/{ids[0]}/cancel", headers=bearer(token)).status_code
        == 200
    )
    assert accepted(client, db, settings, token, keep_lane_zip)["status"] == "queued"
    assert upload(client, token, keep_lane_zip).status_code == 429
    # Failed through the agent's fault (it crashed): still counts, or crashing on purpose would
    # buy free evaluations of the hidden suite.
    with db.session() as session:
        submission = evaluation.lock(session, Submission, ids[1])
        submission.status = SubmissionStatus.failed
    assert upload(client, token, keep_lane_zip).status_code == 429
    # Failed on our side: the try is given back.
    with db.session() as session:
        evaluation.lock(session, Submission, ids[1]).failed_on_our_side = True
    assert upload(client, token, keep_lane_zip).status_code == 202


def test_cancel_once_then_conflict(client, db, keep_lane_zip):
    _, token = make_team(db, "alpha")
    sid = upload(client, token, keep_lane_zip).json()["id"]
    response = client.post(f"/api/v1/submissions/{sid}/cancel", headers=bearer(token))
    assert response.status_code == 200
    assert response.json()["status"] == "cancelled"
    again = client.post(f"/api/v1/submissions/{sid}/cancel", headers=bearer(token))
    assert again.status_code == 409


def test_upload_declared_over_the_cap_is_refused_before_reading(client, db, settings):
    _, token = make_team(db, "alpha")
    too_big = settings.intake.max_zip_bytes + 50 * 2**20

    def body():  # never consumed: the declared length is enough to refuse
        raise AssertionError("the server read the body of an oversized upload")
        yield b""

    response = client.post(
        "/api/v1/submissions",
        headers={
            **bearer(token),
            "Content-Type": "multipart/form-data; boundary=x",
            "Content-Length": str(too_big),
        },
        content=body(),
    )
    assert response.status_code == 413
    assert "MiB" in response.json()["detail"]
    assert count_submissions(db) == 0


@pytest.mark.slow  # the intake in the service's sandbox
def test_an_offline_submission_without_train_py_is_rejected_before_its_requirements(
    client, db, settings, keep_lane_zip
):
    team_id, token = make_team(db, "alpha")
    with zipfile.ZipFile(io.BytesIO(keep_lane_zip)) as archive:
        entries = {name: archive.read(name) for name in archive.namelist()}
    # A requirement that cannot resolve: reached only if train-missing were judged after it.
    entries["requirements.txt"] = b"no-such-project-anywhere==0.0.1\n"
    body = accepted(client, db, settings, token, zip_bytes(entries), track="offline")
    assert body["status"] == "rejected"
    assert "train.py" in body["status_reason"] and "train-missing" in body["status_reason"]
    assert not (settings.storage.resolved_data_dir / "deps").exists() or not any(
        (settings.storage.resolved_data_dir / "deps").iterdir()
    )
    with db.session() as session:
        assert quota_used(session, team_id, "final", Track.offline, utcnow()) == 0


@pytest.mark.slow  # the intake in the service's sandbox
def test_a_train_py_that_does_not_compile_is_named(client, db, settings, keep_lane_zip):
    _, token = make_team(db, "alpha")
    with zipfile.ZipFile(io.BytesIO(keep_lane_zip)) as archive:
        entries = {name: archive.read(name) for name in archive.namelist()}
    body = accepted(
        client,
        db,
        settings,
        token,
        zip_bytes({**entries, "train.py": b"def fit(:\n"}),
        track="offline",
    )
    assert body["status"] == "rejected"
    assert "train-syntax" in body["status_reason"]


def test_offline_uploads_are_refused_while_the_service_has_no_dataset(
    client, db, settings, tmp_path
):
    from server.api.deps import get_settings_dep

    _, token = make_team(db, "alpha")
    no_dataset = with_fields(settings, training={"train_dataset_dir": None})
    client.app.dependency_overrides[get_settings_dep] = lambda: no_dataset
    try:
        response = upload(
            client, token, pack_example("offline_bc", tmp_path).read_bytes(), track="offline"
        )
    finally:
        client.app.dependency_overrides.clear()
    assert response.status_code == 422
    assert "ARENA_TRAIN_DATASET_DIR" in response.json()["detail"]
    assert count_submissions(db) == 0


@pytest.mark.slow  # the intake in the service's sandbox
def test_parallel_uploads_take_one_validation_slot_and_one_try(client, db, settings, keep_lane_zip):
    """With one try left, six parallel uploads once cost 4.7 intakes: the quota was checked
    again only after each. Now the slot is reserved first, atomically: one upload is validated,
    the others are refused before any work on their zip."""
    from concurrent.futures import ThreadPoolExecutor

    _, token = make_team(db, "alpha")
    for _ in range(settings.service.daily_quota - 1):
        assert accepted(client, db, settings, token, keep_lane_zip)["status"] == "queued"
    with ThreadPoolExecutor(6) as pool:
        answers = list(pool.map(lambda _: upload(client, token, keep_lane_zip), range(6)))
    codes = sorted(answer.status_code for answer in answers)
    # 409: refused by the taken slot, with nothing done on the zip (not 429 after an intake).
    assert codes == [202, 409, 409, 409, 409, 409], codes
    assert count_submissions(db) == settings.service.daily_quota
    assert validate_uploads(db, settings) == [
        next(a.json()["id"] for a in answers if a.status_code == 202)
    ]
    assert upload(client, token, keep_lane_zip).status_code == 429
