"""`arena admin ...` against a real database (both backends), configured like a deployment:
through ARENA_* environment variables."""

from __future__ import annotations

import csv
import io
import json
import re

import pytest
from typer.testing import CliRunner

from arena.config import get_settings
from arena_command import app
from server.models import Submission
from server.status import SubmissionStatus
from tests.server.builders import make_team, queued_submission, seed_scored
from tests.server.worker.test_evaluation_flow import run_everything, start

runner = CliRunner()


def test_db_upgrade_is_idempotent(arena):
    from server.core.migrate import head_revision

    assert f"revision {head_revision()}" in arena("db", "upgrade")


def test_teams_create_list_rotate(arena, client):
    output = arena("teams", "create", "gamma")
    token = output.splitlines()[-1]  # alone on the last line
    assert re.fullmatch(r"arena_\S+", token)
    assert (
        client.get("/api/v1/submissions", headers={"Authorization": f"Bearer {token}"}).status_code
        == 200
    )
    assert "already exists" in arena("teams", "create", "gamma", ok=False)
    assert "no team named 'gama'; did you mean 'gamma'?" in arena(
        "teams", "rotate-token", "gama", ok=False
    )
    assert "gamma" in arena("teams", "list")
    new = re.search(r"(arena_\S+)", arena("teams", "rotate-token", "gamma")).group(1)
    assert (
        client.get("/api/v1/submissions", headers={"Authorization": f"Bearer {token}"}).status_code
        == 401
    )
    assert (
        client.get("/api/v1/submissions", headers={"Authorization": f"Bearer {new}"}).status_code
        == 200
    )


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


def test_rescore_rerun_and_export(arena, db, settings):
    team, _ = make_team(db, "alpha")
    sid = queued_submission(db, team)
    run_everything(db, settings, start(db, settings, sid))
    output = arena("rescore", str(sid))
    assert "\t100.0\t" in output  # time of three successes at step 100, as every view writes it
    arena("rescore", "--all")
    refused = arena("rescore", "--phase", "final", "--profile", "nope", ok=False)
    assert "unknown scoring profile" in refused
    assert "attempt 2 queued" in arena("rerun", str(sid))
    # The old score stands meanwhile; the list says a re-run is going on, not just "scored".
    row = arena("submissions", "list").splitlines()[1].split("\t")
    # Its progress as its team sees it in a hidden phase: quarters (services/hidden_timing.py).
    assert (row[5], row[6]) == ("scored (re-run running)", "0/4 quarters")
    rows = list(csv.DictReader(io.StringIO(arena("leaderboard", "export"))))
    assert [(row["team"], float(row["completion"])) for row in rows] == [("alpha", 0.0)]
    # Alone on the board: its rank is certain and there is no neighbour to beat.
    assert (rows[0]["rank_range"], rows[0]["beats_next"]) == ("1", "")


def test_status_reports_queue_and_stuck_runs(arena, db):
    output = arena("status")
    assert "queue depth:" in output and "stuck runs: none" in output


@pytest.mark.parametrize(
    "args",
    [
        ("submissions", "show", str(2**63)),
        ("submissions", "show", str(2**31)),
        ("submissions", "cancel", str(2**64)),
        ("submissions", "disqualify", "0"),
        ("submissions", "requeue", str(2**63)),
        ("rerun", str(2**63)),
        ("rescore", str(2**63)),
        ("submissions", "list", "--limit", "-1"),
        ("leaderboard", "export", "--track", "bogus"),
        ("leaderboard", "export", "--out", "/proc/no/such/folder/board.csv"),
        ("leaderboard", "export", "--out", "/"),
    ],
)
def test_bad_input_gets_a_message_not_a_traceback(arena, args):
    output = arena(*args, ok=False)
    assert "Traceback" not in output
    assert any(word in output for word in ("error", "Invalid value", "not in the range")), output


def test_leaderboard_export_names_the_tracks_and_the_unwritable_file(arena):
    refused = arena("leaderboard", "export", "--track", "bogus", ok=False)
    assert "'bogus' is not one of" in refused and "freestyle" in refused
    assert "Traceback" not in refused
    assert "no phase 'finale'" in arena("leaderboard", "export", "--phase", "finale", ok=False)
    unwritable = arena("leaderboard", "export", "--out", "/", ok=False)
    assert "cannot write /: Is a directory" in unwritable


def test_phases_set_episodes_says_the_cost_and_list_shows_it(arena, client):
    output = arena("phases", "set", "final", "--episodes", "3")
    assert "3 episodes per reactive scenario: evaluation takes about 3 times as long" in output
    listing = arena("phases", "list")
    final = next(line for line in listing.splitlines() if line.startswith("final"))
    assert final.split("\t")[6] == "3"
    assert "1 to 64" in arena("phases", "set", "final", "--episodes", "0", ok=False)
    page = client.get("/submit").text
    assert "3 episodes per reactive scenario: evaluation takes about 3 times as long" in page


def test_phases_set_cpu_limits_and_back_to_the_settings(arena, client):
    output = arena(
        "phases", "set", "final", "--step-cpu", "0.5", "--episode-cpu", "60",
        "--evaluation-cpu", "3600",
    )  # fmt: skip
    assert "agent CPU: 0.5 s per act, 60 s per episode, 3600 s per evaluation" in output
    listing = arena("phases", "list")
    final = next(line for line in listing.splitlines() if line.startswith("final"))
    assert final.split("\t")[7] == "0.5 / 60 / 3600"
    assert "must grow" in arena("phases", "set", "final", "--step-cpu", "120", ok=False)
    assert "more than 0" in arena("phases", "set", "final", "--evaluation-cpu", "0", ok=False)
    output = arena("phases", "set", "final", "--default-cpu-limits")
    assert "agent CPU: 1 s per act, 600 s per episode, 64800 s per evaluation" in output


def test_without_a_database_admin_says_what_to_do_and_creates_nothing(tmp_path, monkeypatch):
    """No ARENA_DATA_DIR: a message naming `arena up` and the settings, no ./.arena/arena.db, no
    traceback; a database file without the schema is named as not migrated."""
    for name in ("DATA_DIR", "DATABASE_URL", "BROKER_URL"):
        monkeypatch.delenv(f"ARENA_{name}", raising=False)
    monkeypatch.chdir(tmp_path)
    get_settings.cache_clear()
    try:
        for args in (("teams", "list"), ("status",), ("submissions", "list")):
            result = runner.invoke(app, ["admin", *args])
            assert result.exit_code == 1
            assert "no database at" in result.output and "arena up" in result.output
            assert "ARENA_DATA_DIR" in result.output and "ARENA_DATABASE_URL" in result.output
            assert "Traceback" not in result.output and len(result.output.splitlines()) <= 3
        assert not (tmp_path / ".arena").exists()
        (tmp_path / ".arena").mkdir()
        (tmp_path / ".arena" / "arena.db").write_bytes(b"")
        result = runner.invoke(app, ["admin", "teams", "list"])
        assert result.exit_code == 1 and "not migrated" in result.output
        assert "arena admin db upgrade" in result.output
    finally:
        get_settings.cache_clear()


def test_a_phase_on_a_missing_suite_is_refused_and_nothing_saved(arena):
    refused = arena(
        "phases", "create", "warmup", "--suite", "nonexistent", "--open-ended", ok=False
    )  # fmt: skip
    assert "suite 'nonexistent'" in refused and "nothing saved" in refused
    assert "warmup" not in arena("phases", "list")
    assert "1 to 64" in arena("phases", "set", "final", "--episodes", "1000", ok=False)
    assert "end after it starts" in arena(
        "phases", "set", "final", "--starts", "2030-01-02", "--ends", "2030-01-01", ok=False
    )
    assert "unknown scoring profile" in arena("phases", "set", "final", "--profile", "x", ok=False)


def test_a_typo_in_phases_set_creates_nothing_and_names_the_nearest_phase(arena, client):
    """`phases set fianl --suite hidden` once opened a new live phase with no end date."""
    refused = arena("phases", "set", "fianl", "--suite", "hidden", ok=False)
    assert "no phase 'fianl'; did you mean 'final'?" in refused
    assert "arena admin phases create fianl" in refused
    assert "fianl" not in arena("phases", "list") and "fianl" not in client.get("/submit").text
    # Creating is its own command: it says when the phase closes, and never overwrites one.
    assert "--ends T, or --open-ended" in arena(
        "phases", "create", "warmup", "--suite", "public", ok=False
    )
    assert "--suite" in arena("phases", "create", "warmup", "--ends", "2030-01-01", ok=False)
    output = arena("phases", "create", "warmup", "--suite", "public", "--ends", "2099-01-01")
    assert "phase warmup created" in output
    warmup = next(
        line for line in arena("phases", "list").splitlines() if line.startswith("warmup")
    )
    assert warmup.split("\t")[4] == "2099-01-01 00:00" and warmup.split("\t")[-1] == "yes"
    again = arena("phases", "create", "final", "--suite", "public", "--open-ended", ok=False)
    assert "phase 'final' exists" in again and "phases set final" in again


def test_phases_list_shows_a_broken_phase_as_not_open(arena, settings):
    import shutil

    shutil.rmtree(settings.suites.hidden_suite_dir)
    listing = arena("phases", "list")
    final = next(line for line in listing.splitlines() if line.startswith("final"))
    assert final.split("\t")[-1] == "no: broken"
    assert "BROKEN phase 'final': suite 'hidden'" in listing


def test_status_lists_overdue_work_and_broken_phases(arena, db, settings, monkeypatch):
    from datetime import timedelta

    from server.models import utcnow

    team, _ = make_team(db, "alpha")
    late = queued_submission(db, team)
    with db.session() as session:
        session.get(Submission, late).queued_at = utcnow() - timedelta(hours=2)
    queued_submission(db, team)  # queued just now: not overdue
    output = arena("status")
    assert "broken phases: none" in output
    overdue = output.split("# overdue")[1].splitlines()[2:]  # after the title and header
    assert [line.split("\t")[:4] for line in overdue] == [[str(late), "alpha", "final", "queued"]]
    import shutil

    shutil.rmtree(settings.suites.hidden_suite_dir)
    output = arena("status")
    assert "BROKEN PHASES" in output and "final\tphase 'final': suite 'hidden'" in output


def test_disqualify_needs_a_reason_and_says_when_already_done(arena, db):
    team, _ = make_team(db, "alpha")
    scored = seed_scored(db, team, (0.5, 400.0, 0.1, 0.0))
    assert "Missing option '--reason'" in arena("submissions", "disqualify", str(scored), ok=False)
    blank = arena("submissions", "disqualify", str(scored), "--reason", " ", ok=False)
    assert "give the reason the team is shown" in blank
    arena("submissions", "disqualify", str(scored), "--reason", "copied code")
    again = arena("submissions", "disqualify", str(scored), "--reason", "again", ok=False)
    assert "already disqualified (reason: copied code)" in again


def test_rescore_with_another_profile_is_for_a_whole_phase(arena, db, settings):
    team, _ = make_team(db, "alpha")
    first = queued_submission(db, team)
    run_everything(db, settings, start(db, settings, first))
    second = queued_submission(db, team)
    run_everything(db, settings, start(db, settings, second))
    refused = arena("rescore", str(first), "--profile", "driving-smarts-2022", ok=False)
    assert "give --phase NAME" in refused and "ranked unfairly" in refused
    assert "give --phase" in arena("rescore", "--all", "--profile", "driving-smarts-2022", ok=False)
    output = arena("rescore", "--phase", "final", "--profile", "driving-smarts-2022")
    assert "phase final is now scored with profile driving-smarts-2022" in output
    rows = [line.split("\t") for line in output.splitlines() if line[:1].isdigit()]
    # Submission ids, not run ids; every submission of the phase, by the same profile.
    assert [(row[0], row[2], row[3]) for row in rows] == [
        (str(first), "final", "driving-smarts-2022"),
        (str(second), "final", "driving-smarts-2022"),
    ]
    assert arena("rescore", str(second)).splitlines()[-1].startswith(f"{second}\t1\tfinal\t")


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


def test_delete_a_team_and_a_phase_says_what_goes_and_asks(arena, db, settings):
    team, _ = make_team(db, "alpha")
    other, _ = make_team(db, "beta")
    sid = queued_submission(db, team)
    run_everything(db, settings, start(db, settings, sid))
    kept = seed_scored(db, other, (0.5, 400.0, 0.1, 0.0), phase="validation")
    result = runner.invoke(app, ["admin", "teams", "delete", "alpha"], input="n\n")
    assert result.exit_code == 1 and "nothing deleted" in result.output
    assert "team alpha: 1 submission(s) with their uploads, 1 evaluation(s)" in result.output
    assert "3 episode result(s)" in result.output and "1 API token(s)" in result.output
    assert "alpha" in arena("teams", "list")
    result = runner.invoke(app, ["admin", "teams", "delete", "alpha"], input="y\n")
    assert result.exit_code == 0 and "deleted team alpha" in result.output
    assert "alpha" not in arena("teams", "list")
    with db.session() as session:
        assert session.get(Submission, sid) is None
        assert session.get(Submission, kept) is not None
    refused = arena("phases", "delete", "final", "--yes", ok=False)
    assert "cannot be deleted" in refused
    assert "phase validation: 1 submission(s)" in arena("phases", "delete", "validation", "--yes")
    assert "validation" not in arena("phases", "list")
    assert "no team named 'alpha'" in arena("teams", "delete", "alpha", "--yes", ok=False)


def test_compare_two_submissions_of_a_hidden_phase(arena, db, settings):
    team, _ = make_team(db, "alpha")
    worse = queued_submission(db, team)
    run_everything(db, settings, start(db, settings, worse), success=False)
    better = queued_submission(db, team)
    run_everything(db, settings, start(db, settings, better), success=True)
    output = arena("compare", str(worse), str(better))
    assert f"A: submission {worse} of alpha (final, attempt 1" in output
    lines = [line.split("\t") for line in output.splitlines()]
    # B - A, and B - A paired over the scenarios both ran: every one differs alike.
    assert next(row for row in lines if row[0] == "completion")[1:] == [
        "1.0000",
        "0.0000",
        "-1.0000",
        "[-1.0000, -1.0000] B better",
    ]
    ahead = next(row for row in lines if row[0] == "B ranks ahead of A")
    assert ahead[-1] == "100.0% of resamples over 3 shared scenarios"
    assert "3 episode(s) ended differently" in output
    document = json.loads(arena("compare", str(worse), str(better), "--json"))
    assert {row["b"] for row in document["differing_outcomes"]} == {"reached_goal"}
    paired = document["paired"]
    assert (paired["scenarios"], paired["b_ranks_ahead"]) == (3, 1.0)
    assert paired["completion"] == {"b_minus_a": -1.0, "low": -1.0, "high": -1.0}
    queued = queued_submission(db, team)
    assert "no score yet" in arena("compare", str(worse), str(queued), ok=False)


def test_phases_set_adaptive_says_the_cost_before_and_after_and_list_shows_it(arena, client):
    cost = (
        "adaptive: 2 episode(s) per reactive scenario, then 2 more per round while completion's "
        "95% interval is wider than +/-0.05, up to 20: evaluation takes 2 to 20 times as long"
    )
    args = ("phases", "set", "final", "--episodes", "2", "--adaptive-target", "0.05")
    preview = arena(*args, "--max-episodes", "20", "--dry-run")
    assert cost in " ".join(preview.split()) and "unchanged (dry run)" in preview
    assert "adaptive" not in arena("phases", "list")
    assert cost in " ".join(arena(*args, "--max-episodes", "20").split())
    assert f"final (+): {cost}" in " ".join(arena("phases", "list").split())
    assert cost.replace("'", "&#39;") in " ".join(client.get("/submit").text.split())
    assert "both" in arena(*args, ok=False)
    arena("phases", "set", "final", "--fixed-episodes")
    assert "adaptive" not in arena("phases", "list")


def test_phases_release_waits_for_the_close_and_list_says_it(arena):
    refused = arena("phases", "release", "final", ok=False)
    assert "has no end date" in refused and "Traceback" not in refused
    arena("phases", "set", "final", "--ends", "2020-01-01T00:00")
    done = " ".join(arena("phases", "release", "final").split())
    assert "released" in done and "/api/v1/scenarios/released/final.zip" in done
    assert "released (suite downloadable, episodes visible): final" in arena("phases", "list")


def test_leaderboard_export_with_the_generalisation_gap(arena, db):
    team, _ = make_team(db, "a")
    seed_scored(db, team, (0.5, 400.0, 0.5, 0.1), phase="final")
    seed_scored(db, team, (0.25, 300.0, 0.5, 0.1), phase="validation")
    text = arena("leaderboard", "export", "--gap-from", "validation")
    rows = list(csv.DictReader(io.StringIO(text)))
    assert (rows[0]["team"], float(rows[0]["gap_completion"])) == ("a", 0.25)
    assert "no phase 'nope'" in arena("leaderboard", "export", "--gap-from", "nope", ok=False)


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


def test_a_long_command_piped_says_its_progress_on_stderr_at_a_bounded_rate(capsys):
    """`arena admin audit | tee` once printed nothing for minutes: piped, its progress is plain
    lines on stderr, the first episode and the last at once, between them one per interval."""
    from server.cli import _episode_progress

    with _episode_progress("submission 7") as step:
        for done in range(1, 129):
            step(done, 128)
    captured = capsys.readouterr()
    assert captured.out == ""
    assert captured.err.splitlines() == [
        "submission 7: 1/128 episodes re-run",
        "submission 7: 128/128 episodes re-run",
    ]


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
