"""`arena admin submissions ...` (server/commands/submissions.py and the detail lines of `show`,
server/commands/submission_detail.py). Run against a real database (both backends), configured
like a deployment: through ARENA_* environment variables."""

from __future__ import annotations

import json

from server.models import Submission
from server.status import SubmissionStatus
from tests.server.builders import make_team, queued_submission, seed_scored
from tests.server.worker.test_evaluation_flow import start


def test_submissions_list_show_cancel_disqualify_requeue(arena, db):
    team, _ = make_team(db, "alpha")
    queued = queued_submission(db, team)
    scored = seed_scored(db, team, (0.5, 400.0, 0.1, 0.0))
    listing = arena("submissions", "list")
    # Not a terminal: a header and one tab-separated line per submission, nothing wrapped.
    lines = listing.splitlines()
    assert lines[0].split("\t")[:6] == ["id", "team", "phase", "track", "method", "status"]
    assert [line.split("\t")[5] for line in lines[1:]] == ["scored", "queued"]
    assert [line.split("\t")[2] for line in lines[1:]] == ["final", "final"]
    listed = json.loads(arena("submissions", "list", "--json"))
    assert [(row["id"], row["status"]) for row in listed] == [
        (scored, "scored"),
        (queued, "queued"),
    ]
    assert json.loads(arena("teams", "list", "--json"))[0]["team"] == "alpha"
    shown = json.loads(arena("submissions", "show", str(queued), "--json"))
    assert shown["status"] == "queued" and shown["attempts"] == []
    text = arena("submissions", "show", str(queued))
    assert "status: queued" in text and "{" not in text  # lines, not JSON mixed with tables
    assert "evaluation queued" in arena("submissions", "requeue", str(queued))
    arena("submissions", "cancel", str(queued))
    assert "cannot cancel" in arena("submissions", "cancel", str(queued), ok=False)
    arena("submissions", "disqualify", str(scored), "--reason", "copied code")
    with db.session() as session:
        assert session.get(Submission, queued).status == SubmissionStatus.cancelled
        assert session.get(Submission, scored).status == SubmissionStatus.disqualified
        assert session.get(Submission, scored).status_reason == "copied code"
    assert "no submission 999" in arena("submissions", "show", "999", ok=False)


def test_disqualify_needs_a_reason_and_says_when_already_done(arena, db):
    team, _ = make_team(db, "alpha")
    scored = seed_scored(db, team, (0.5, 400.0, 0.1, 0.0))
    assert "Missing option '--reason'" in arena("submissions", "disqualify", str(scored), ok=False)
    blank = arena("submissions", "disqualify", str(scored), "--reason", " ", ok=False)
    assert "give the reason the team is shown" in blank
    arena("submissions", "disqualify", str(scored), "--reason", "copied code")
    again = arena("submissions", "disqualify", str(scored), "--reason", "again", ok=False)
    assert "already disqualified (reason: copied code)" in again


def test_requeue_leaves_a_healthy_evaluation_alone_and_resends_only_lost_work(arena, db, settings):
    from datetime import timedelta

    from sqlalchemy import select, update

    from server.models import EvaluationRun, ScenarioResult, utcnow
    from tests.server.builders import scenario_ids
    from tests.server.worker.test_evaluation_flow import claim

    team, _ = make_team(db, "alpha")
    sid = queued_submission(db, team)
    plan = start(db, settings, sid)
    held, *rest = scenario_ids(plan)
    claim(db, settings, plan.run_id, held)
    refused = arena("submissions", "requeue", str(sid), ok=False)
    assert "is alive" in refused and "nothing is re-sent" in refused
    # The run's lease ran out (no worker renewed it) but one claim is still live: only the
    # episodes nobody holds go out again.
    with db.session() as session:
        session.execute(
            update(EvaluationRun).values(lease_expires_at=utcnow() - timedelta(seconds=1))
        )
    assert f"{len(rest)} episode(s) re-sent" in arena("submissions", "requeue", str(sid))
    with db.session() as session:
        claim_row = session.scalar(select(ScenarioResult).where(ScenarioResult.scenario_id == held))
        assert claim_row.worker == "w1"  # the live claim is untouched
        session.execute(
            update(EvaluationRun).values(lease_expires_at=utcnow() - timedelta(seconds=1))
        )
        claim_row.lease_expires_at = utcnow() - timedelta(seconds=1)
    assert f"{len(rest) + 1} episode(s) re-sent" in arena("submissions", "requeue", str(sid))


def test_submissions_show_prints_the_manifest(arena, db, settings):
    from tests.server.services.test_manifest import run_with_pins

    team, _ = make_team(db, "alpha")
    sid = queued_submission(db, team)
    run_with_pins(db, settings, sid)
    shown = " ".join(arena("submissions", "show", str(sid)).split())
    assert "3 scenarios" in shown and "profile driving-smarts-2022 v1" in shown
    assert "arena 0.1.0, Python 3.11.7, numpy 2.4.6, SUMO 1.28.0, docker, image sha256:" in shown
    document = json.loads(arena("submissions", "show", str(sid), "--json"))
    assert document["manifest"]["environments"][0]["sumo"] == "1.28.0"


def test_submissions_show_counts_a_hidden_runs_episodes_exactly_and_says_never_scored(
    arena, db, settings
):
    """It once printed `progress: 0/128` (the team's coarse view of a hidden phase's run) beside
    a table of finished episodes, and "scored before manifests were kept" for a submission never
    scored."""
    from tests.server.builders import report_episode

    team, _ = make_team(db, "alpha")
    sid = queued_submission(db, team)
    plan = start(db, settings, sid)  # the final phase: hidden
    for episode in plan.episodes[:2]:
        report_episode(db, settings, plan, episode, reached_goal=True)
    shown = arena("submissions", "show", str(sid))
    assert f"progress: 2/{len(plan.episodes)}" in shown
    assert shown.count("reached_goal") == 2
    assert "manifest: - (not scored)" in shown and "manifests were kept" not in shown
