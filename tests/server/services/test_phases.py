"""Competition phases: dates, quotas and leaderboards per phase, and what a team may see of its
own evaluation in a hidden phase (nothing its agent wrote, no per-scenario detail)."""

from __future__ import annotations

from datetime import timedelta

import pytest

from server.models import utcnow
from server.services import phases
from server.services.errors import InvalidInput
from server.services.leaderboard import LeaderboardCache
from server.tracks import Track
from tests.server.builders import (
    bearer,
    evaluate_failing_everywhere,
    make_team,
    pack_example,
    queued_submission,
    seed_scored,
    validate_uploads,
)

SECRET = "obs: start=(12.5, -3.2) goal=(310.0, 4.8) agent printed this"


@pytest.fixture
def keep_lane_zip(tmp_path) -> bytes:
    return pack_example("keep_lane", tmp_path).read_bytes()


def upload(client, token, payload: bytes, **fields):
    return client.post(
        "/api/v1/submissions",
        headers=bearer(token),
        data={"track": "freestyle", "method_name": "m", **fields},
        files={"file": ("agent.zip", payload, "application/zip")},
    )


@pytest.fixture
def set_phase(db, settings):
    def change(name, **changes):
        return phases.set_phase(db, settings, name, phases.PhaseChanges(**changes))

    return change


@pytest.fixture
def create_phase(db, settings):
    def create(name, **changes):
        return phases.create_phase(db, settings, name, phases.PhaseChanges(**changes))

    return create


def test_changing_a_phase_never_creates_one(db, set_phase, create_phase):
    from server.services.errors import Conflict, NotFound

    with pytest.raises(NotFound, match=r"no phase 'fianl'; did you mean 'final'\?"):
        set_phase("fianl", suite="hidden")
    with pytest.raises(NotFound, match=r"no phase 'warmup' \(phases: validation, final\)"):
        set_phase("warmup", suite="public")
    with pytest.raises(InvalidInput, match="--ends T, or --open-ended"):
        create_phase("warmup", suite="public")
    with pytest.raises(Conflict, match="phase 'final' exists"):
        create_phase("final", suite="public", clear_dates=True)
    with db.session() as session:
        assert [p.name for p in phases.list_phases(session)] == ["validation", "final"]
        # The lookup every command and upload goes through suggests the nearest name too.
        with pytest.raises(NotFound, match="did you mean 'validation'"):
            phases.get_phase(session, "validaton")


@pytest.mark.slow  # the intake in the service's sandbox
def test_upload_names_its_phase_and_defaults_to_final(client, db, settings, keep_lane_zip):
    _, token = make_team(db, "alpha")
    assert upload(client, token, keep_lane_zip).json()["phase"] == "final"
    validate_uploads(db, settings)  # a team has one upload validating at a time
    body = upload(client, token, keep_lane_zip, phase="validation").json()
    assert body["phase"] == "validation"


def test_unknown_phase_is_refused_naming_the_phases(client, db, keep_lane_zip):
    _, token = make_team(db, "alpha")
    response = upload(client, token, keep_lane_zip, phase="finale")
    assert response.status_code == 422
    assert "validation, final" in response.json()["detail"]


def test_uploads_outside_a_phase_are_refused_saying_when(client, db, keep_lane_zip, set_phase):
    _, token = make_team(db, "alpha")
    later = (utcnow() + timedelta(days=2)).replace(second=0, microsecond=0)
    set_phase("final", starts_at=later)
    response = upload(client, token, keep_lane_zip)
    assert response.status_code == 403
    assert f"opens for submissions at {later:%Y-%m-%d %H:%M} UTC" in response.json()["detail"]
    set_phase("validation", ends_at=utcnow() - timedelta(hours=1))
    response = upload(client, token, keep_lane_zip, phase="validation")
    assert response.status_code == 403
    assert "closed for submissions" in response.json()["detail"]
    set_phase("final", clear_dates=True)
    assert upload(client, token, keep_lane_zip).status_code == 202


@pytest.mark.slow  # the intake in the service's sandbox
def test_the_daily_quota_is_per_phase(client, db, settings, keep_lane_zip, set_phase):
    _, token = make_team(db, "alpha")
    set_phase("final", daily_quota=1)
    assert upload(client, token, keep_lane_zip).status_code == 202
    validate_uploads(db, settings)
    refused = upload(client, token, keep_lane_zip)
    assert refused.status_code == 429
    assert "'final' phase" in refused.json()["detail"]
    assert upload(client, token, keep_lane_zip, phase="validation").status_code == 202


def test_after_a_phase_closes_every_view_says_no_uploads_are_left(client, db, set_phase):
    """The submission's standing once said "2 of 3 uploads left today" while GET /team said 0."""
    team, token = make_team(db, "alpha")
    scored = seed_scored(db, team, (0.5, 400.0, 0.1, 0.0))
    set_phase("final", daily_quota=3)

    def left() -> tuple[int, int]:
        detail = client.get(f"/api/v1/submissions/{scored}", headers=bearer(token)).json()
        allowances = client.get("/api/v1/team", headers=bearer(token)).json()["allowances"]
        final = next(
            a for a in allowances if a["phase"]["name"] == "final" and a["track"] == "freestyle"
        )
        return detail["standing"]["tries_left_today"], final["tries_left_today"]

    assert left() == (2, 2)  # the scored submission counts
    set_phase("final", ends_at=utcnow() - timedelta(minutes=1))
    assert left() == (0, 0)


def test_submit_page_offers_the_open_phases_and_says_when_the_others_open(client, db, set_phase):
    """A closed phase stays on the form, disabled, with its date: it does not just vanish."""
    ended = (utcnow() - timedelta(hours=1)).replace(second=0, microsecond=0)
    set_phase("validation", ends_at=ended)
    page = client.get("/submit").text
    assert '<option value="final" selected>' in page
    assert '<option value="validation" disabled>validation</option>' in page
    assert f"validation closed {ended:%Y-%m-%d %H:%M} UTC." in page
    later = (utcnow() + timedelta(days=3)).replace(second=0, microsecond=0)
    set_phase("final", starts_at=later)
    page = client.get("/submit").text
    assert '<option value="final" selected disabled>final</option>' in page
    assert f"final opens {later:%Y-%m-%d %H:%M} UTC." in page
    assert "No phase is open for submissions right now." in page


def finished_submission(db, settings, phase: str) -> int:
    team_id, _ = make_team(db, f"team-{phase}")
    submission_id = queued_submission(db, team_id, phase=phase)
    evaluate_failing_everywhere(db, settings, submission_id, log=SECRET)
    return submission_id


def token_of(db, submission_id) -> str:
    from server.models import Submission
    from server.services import teams

    with db.session() as session:
        team = session.get(Submission, submission_id).team
        return teams.rotate_token(session, team)


def test_a_hidden_phase_gives_the_team_no_agent_output_and_no_scenario_detail(client, db, settings):
    submission_id = finished_submission(db, settings, "final")
    headers = bearer(token_of(db, submission_id))
    logs = client.get(f"/api/v1/submissions/{submission_id}/logs", headers=headers)
    assert logs.status_code == 403
    assert "organisers only" in logs.json()["detail"]
    seen = ""
    for path in (
        f"/api/v1/submissions/{submission_id}",
        "/api/v1/submissions",
        f"/submissions/{submission_id}",
        "/api/v1/leaderboard?phase=final",
        "/api/v1/leaderboard.csv?phase=final",
        "/?phase=final",
    ):
        response = client.get(path, headers=headers)
        assert response.status_code == 200, path
        seen += response.text
    assert SECRET not in seen and "obs:" not in seen
    assert not any(sid in seen for sid in phases_suite_ids(settings))
    detail = client.get(f"/api/v1/submissions/{submission_id}", headers=headers).json()
    assert detail["metrics"]["completion"] == 1.0
    assert detail["failure_reasons"] == {"cruise": {"collision": 2}, "merge": {"collision": 1}}


def phases_suite_ids(settings) -> list[str]:
    from arena.suite import load_suite

    return [entry.id for entry in load_suite(settings.suites.hidden_suite_dir).scenarios]


def test_organisers_read_the_agent_output_of_a_hidden_phase(db, settings):
    from server.models import Submission
    from server.services import submissions

    submission_id = finished_submission(db, settings, "final")
    with db.session() as session:
        view = submissions.logs(session, session.get(Submission, submission_id), organiser=True)
    assert {entry.log_tail for entry in view.scenarios} == {SECRET}
    assert {entry.scenario_id for entry in view.scenarios} == set(phases_suite_ids(settings))


def test_a_validation_phase_shows_the_team_everything(client, db, settings):
    submission_id = finished_submission(db, settings, "validation")
    headers = bearer(token_of(db, submission_id))
    logs = client.get(f"/api/v1/submissions/{submission_id}/logs", headers=headers)
    assert logs.status_code == 200
    entries = logs.json()["scenarios"]
    assert {e["log_tail"] for e in entries} == {SECRET}
    assert {e["scenario_id"] for e in entries} == set(phases_suite_ids(settings))


def test_leaderboards_are_per_phase(client, db):
    alpha, _ = make_team(db, "alpha")
    beta, _ = make_team(db, "beta")
    seed_scored(db, alpha, (0.0, 100.0, 1.0, 0.0), phase="final")
    seed_scored(db, beta, (0.5, 300.0, 1.0, 0.0), phase="validation")
    cache = LeaderboardCache(db, recheck_s=0)
    assert [e.team for e in cache.get(Track.freestyle, "final").board.entries] == ["alpha"]
    assert [e.team for e in cache.get(Track.freestyle, "validation").board.entries] == ["beta"]
    body = client.get("/api/v1/leaderboard?phase=validation").json()
    assert (body["phase"], [e["team"] for e in body["entries"]]) == ("validation", ["beta"])


def test_admin_phase_changes_are_checked(db, set_phase, create_phase):
    with pytest.raises(InvalidInput, match="end after it starts"):
        set_phase("final", starts_at=utcnow(), ends_at=utcnow() - timedelta(days=1))
    with pytest.raises(InvalidInput, match="unknown scoring profile"):
        set_phase("final", scoring_profile="no-such-profile")
    with pytest.raises(InvalidInput, match="needs --suite"):
        create_phase("warmup", clear_dates=True)
    with pytest.raises(InvalidInput, match=r"suite 'nonexistent'.*nothing saved"):
        create_phase("warmup", suite="nonexistent", clear_dates=True)
    with pytest.raises(InvalidInput, match="1 to 64"):
        set_phase("final", episodes_per_scenario=65)
    with pytest.raises(InvalidInput, match="suite '/no/such/folder'"):
        set_phase("final", suite="/no/such/folder")
    create_phase("warmup", suite="public", daily_quota=2, clear_dates=True)
    with db.session() as session:
        assert [p.name for p in phases.list_phases(session)] == ["validation", "final", "warmup"]
        assert phases.get_phase(session, "final").suite == "hidden"  # the refused change


def test_a_phase_broken_after_it_was_set_fails_its_runs_with_a_reason(db, settings, tmp_path):
    """A suite folder removed after the phase was set: the queued submission fails at once with
    a reason (never re-sent forever), and the phase is listed as misconfigured."""
    import shutil

    from server.models import Submission
    from server.services import evaluation
    from server.status import SubmissionStatus

    shutil.rmtree(settings.suites.hidden_suite_dir)
    team_id, _ = make_team(db, "alpha")
    submission_id = queued_submission(db, team_id)
    with db.session() as session:
        assert evaluation.start_evaluation(session, settings, submission_id) is None
    with db.session() as session:
        submission = session.get(Submission, submission_id)
        assert submission.status == SubmissionStatus.failed
        assert "phase 'final'" in submission.status_reason
        assert "organisers" in submission.status_reason
        assert (
            str(settings.suites.hidden_suite_dir) not in submission.status_reason
        )  # a hidden path
        assert set(phases.misconfigured(session, settings)) == {"validation", "final"}


def test_an_upload_to_a_broken_phase_is_refused_and_costs_nothing(
    client, db, settings, keep_lane_zip
):
    import shutil

    _, token = make_team(db, "alpha")
    shutil.rmtree(settings.suites.hidden_suite_dir)
    response = upload(client, token, keep_lane_zip)
    assert response.status_code == 403
    assert "cannot evaluate submissions right now" in response.json()["detail"]
    assert str(settings.suites.hidden_suite_dir) not in response.json()["detail"]
    assert client.get("/api/v1/submissions", headers=bearer(token)).json() == []


@pytest.mark.parametrize("phase", ["final", "validation"])
def test_a_run_that_failed_on_our_side_shows_nothing_per_family_in_a_hidden_phase(
    client, db, settings, phase
):
    """One episode failing on our side (uncharged) makes the run fail; in a hidden phase the
    other episodes' per-family outcomes stay unseen until the run is rerun and scored (they
    were shown: a free look at the hidden suite)."""
    from arena.outcome import AgentOutcome, ScenarioStatus
    from evaluator.runner import ScenarioOutcome
    from server.core.artifacts import DatabaseStore
    from server.services import evaluation
    from tests.server.builders import agent, scenario_ids

    team_id, _ = make_team(db, f"ours-{phase}")
    submission_id = queued_submission(db, team_id, phase=phase)
    with db.session() as session:
        plan = evaluation.start_evaluation(session, settings, submission_id)
    for index, scenario_id in enumerate(scenario_ids(plan)):
        with db.session() as session:
            job = evaluation.claim_scenario(
                session, settings.service, settings.sandbox, plan.run_id, scenario_id, "w1"
            )
        ours = index == 0
        outcome = ScenarioOutcome(
            scenario_id=scenario_id,
            status=ScenarioStatus.simulator_error if ours else ScenarioStatus.done,
            steps=0,
            agents=() if ours else (AgentOutcome(**agent(False)),),
            record_path=None,
            error="SUMO crashed" if ours else None,
        )
        with db.session() as session:
            evaluation.record_scenario(session, job, "w1", outcome, "")
    with db.session() as session:
        evaluation.finish_run(session, DatabaseStore(db), plan.run_id)
    headers = bearer(token_of(db, submission_id))
    detail = client.get(f"/api/v1/submissions/{submission_id}", headers=headers).json()
    if phase == "final":
        assert detail["failure_reasons"] == {} and detail["families"] == {}
    else:
        assert "collision" in str(detail["failure_reasons"])
