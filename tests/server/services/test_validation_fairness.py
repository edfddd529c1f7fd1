"""Issue 40: validation time is the team's and fairly shared. A zip of ~500 one-MiB files kept a
validation busy for 300 s, its rejection was free, and another team's upload waited 299 s behind
it. Now every claim is charged the time it held its worker, rejected or not; a task claims the
waiting validation of the team that used the least today; a validation that has run a slice
yields to a team that used less; a team past its daily budget cannot upload."""

from __future__ import annotations

from datetime import timedelta

import pytest

from server.jobs.kind import HAND_BACK
from server.models import Submission, UploadValidation, utcnow
from server.services import submissions, validation
from server.services.errors import QuotaExceeded
from server.tracks import Track
from tests.server.builders import make_team
from tests.settings import with_fields

FIELDS = {"phase": "validation", "method_name": "m", "track": Track.freestyle}


def upload(db, settings, team_id: int) -> int:
    """A stored upload waiting for its validation, as the API leaves it."""
    submission_id, _ = validation.reserve(
        db, settings.service, team_id, dict(FIELDS), check_quota=lambda session: None
    )
    return submission_id


def claim(db, settings, worker: str = "w1") -> validation.ValidationClaim | None:
    with db.session() as session:
        return validation.claim(session, settings.service, settings.intake, worker)


def ran_for(db, submission_id: int, seconds: float) -> None:
    """The claim of ``submission_id`` took its worker ``seconds`` ago."""
    with db.session() as session:
        job = session.query(UploadValidation).filter_by(submission_id=submission_id).one()
        job.claimed_at = utcnow() - timedelta(seconds=seconds)


def reject(db, claimed: validation.ValidationClaim, worker: str = "w1") -> None:
    with db.session() as session:
        assert validation.record_rejected(session, claimed, worker, "rule broken", ours=False)


def used(db, team_id: int) -> float:
    with db.read_session() as session:
        return validation.used_today(session, team_id, utcnow())


def test_a_rejection_is_charged_the_time_it_took(db, settings) -> None:
    team, _ = make_team(db, "hostile")
    first = upload(db, settings, team)
    claimed = claim(db, settings)
    assert claimed.submission_id == first
    ran_for(db, first, 300)
    reject(db, claimed)
    assert used(db, team) == pytest.approx(300, abs=2)


def test_a_task_claims_the_validation_of_the_team_that_used_least(db, settings) -> None:
    hostile, _ = make_team(db, "hostile")
    other, _ = make_team(db, "other")
    spent = upload(db, settings, hostile)
    claimed = claim(db, settings)
    ran_for(db, spent, 300)
    reject(db, claimed)
    # The hostile team uploads again, first; the other team after it.
    again = upload(db, settings, hostile)
    theirs = upload(db, settings, other)
    assert claim(db, settings).submission_id == theirs  # whichever task was delivered
    assert claim(db, settings, "w2").submission_id == again
    assert claim(db, settings, "w3") is None  # nothing else waits unheld


def test_a_long_validation_yields_to_a_team_that_used_less(db, settings) -> None:
    hostile, _ = make_team(db, "hostile")
    other, _ = make_team(db, "other")
    slow = upload(db, settings, hostile)
    claimed = claim(db, settings)
    ran_for(db, slow, settings.intake.validation_slice_s + 1)
    with db.session() as session:  # nobody else waits: it keeps its worker
        assert validation.renew(session, settings.service, claimed, "w1") is True
    theirs = upload(db, settings, other)
    with db.session() as session:
        assert validation.renew(session, settings.service, claimed, "w1") == HAND_BACK
    with db.session() as session:  # handed back: charged, and not a claim a worker died with
        assert validation.release(session, claimed, "w1")
    assert used(db, hostile) == pytest.approx(settings.intake.validation_slice_s + 1, abs=2)
    assert claim(db, settings).submission_id == theirs
    resumed = claim(db, settings, "w2")
    assert (resumed.submission_id, resumed.claim_number) == (slow, 1)


def test_a_validation_runs_at_most_what_is_left_of_the_budget(db, settings) -> None:
    team, _ = make_team(db, "team")
    first = upload(db, settings, team)
    claimed = claim(db, settings)
    assert claimed.time_budget_s == settings.intake.intake_timeout_s
    ran_for(db, first, settings.intake.validation_budget_s - 100)
    reject(db, claimed)
    upload(db, settings, team)
    assert claim(db, settings).time_budget_s == pytest.approx(100, abs=2)


def test_a_team_past_its_budget_cannot_upload_and_others_can(db, settings) -> None:
    tight = with_fields(settings, intake={"validation_budget_s": 60.0})
    spent, _ = make_team(db, "spent")
    fresh, _ = make_team(db, "fresh")
    first = upload(db, tight, spent)
    claimed = claim(db, tight)
    ran_for(db, first, 61)
    reject(db, claimed)
    with db.session() as session, pytest.raises(QuotaExceeded) as refused:
        submissions.check_quota(session, tight, spent, "validation", "freestyle")
    assert "validation time" in str(refused.value) and "00:00 UTC" in str(refused.value)
    with db.session() as session:
        submissions.check_quota(session, tight, fresh, "validation", "freestyle")
        assert session.get(Submission, first).status == "rejected"
