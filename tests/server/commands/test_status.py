"""`arena admin status` (server/commands/status.py). Run against a real database (both backends),
configured like a deployment: through ARENA_* environment variables."""

from __future__ import annotations

import re

from server.models import Submission
from tests.server.builders import make_team, queued_submission


def test_status_reports_queue_workers_and_stuck_runs(arena, settings):
    """Redis reaches every worker process: they are pinged and listed. The in-memory broker
    passes messages between the threads of one process only, so a ping could only wait out its
    timeout: status says it cannot list them instead."""
    output = arena("status")
    assert "queue depth:" in output and "stuck runs: none" in output
    if settings.storage.resolved_broker_url.startswith("memory://"):
        assert "\nworkers: (the embedded broker cannot list workers)\n" in output
    else:
        assert re.search(r"^workers \(\d+\): ", output, re.MULTILINE), output


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


def test_status_says_which_simulator_core_runs_and_why(arena, db, monkeypatch):
    """For the organiser checking a deployment: the compiled core, or the pure-Python
    reference with its reason (forced here; a core not built names its missing modules)."""
    from sim.compiled import PURE_PYTHON_VARIABLE, core_status

    assert f"\nsimulator core here: {core_status()}\n" in arena("status")
    monkeypatch.setenv(PURE_PYTHON_VARIABLE, "1")
    assert "\nsimulator core here: pure-python (ARENA_PURE_PYTHON)\n" in arena("status")
