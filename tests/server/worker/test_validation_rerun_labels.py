"""A validation handed back is claimed again with the same claim number (``validation.release``
gives it back), and the earlier run's stop hook (``sandbox.cleanup`` by its labels, which the
stopping worker's heartbeat may still run) must not kill the sandbox of the later run. Their
labels once were ``s<id>c<n>`` alone: the later run's intake was killed and the upload rejected
as the team's."""

from __future__ import annotations

import contextlib
import os
import signal
import threading
import time

import pytest

from arena.config import get_settings
from evaluator.sandbox.backend import SANDBOX_LABEL, owner_labels
from evaluator.sandbox.subprocess_sandbox import is_alive, labelled_pids
from server.core.queue import TaskQueue
from server.jobs.kind import Lease
from server.services import validation
from server.services.submissions import NewSubmission, accept_upload
from server.tracks import Track
from server.worker import local
from server.worker.validations import VALIDATIONS
from tests.server.builders import make_team, pack_example
from tests.server.live import export_settings
from tests.settings import with_fields

pytestmark = [pytest.mark.slow, pytest.mark.bwrap]

WORKER = "test-worker"
# [s] How long the later run's intake sandbox may take to appear (polled every POLL_S).
APPEAR_S = 60.0
POLL_S = 0.005


@pytest.fixture
def worker_settings(settings, db, monkeypatch):
    """This process configured as a bubblewrap worker of the test's service."""
    settings = with_fields(settings, sandbox={"kind": "bubblewrap"})
    export_settings(monkeypatch, settings)
    caches = (get_settings, local.database, local.queue, local.store, local.sandbox_kind)
    for cache in caches:
        cache.cache_clear()
    yield get_settings()
    for cache in caches:
        cache.cache_clear()


def claim(db, settings):
    with db.session() as session:
        return validation.claim(session, settings.service, settings.intake, WORKER)


def test_an_earlier_runs_stop_hook_spares_the_rerun_of_its_claim(worker_settings, db, tmp_path):
    settings = worker_settings
    team_id, _ = make_team(db, "alpha")
    zip_path = pack_example("keep_lane", tmp_path)
    queue = TaskQueue(settings)
    try:
        new = NewSubmission(track=Track.freestyle, method_name="m")
        accept_upload(db, settings, queue, team_id, new, zip_path, "0" * 64)
    finally:
        queue.close()

    first = claim(db, settings)
    earlier = Lease(VALIDATIONS, first, WORKER)
    assert VALIDATIONS.run(first, earlier, settings).prepared is not None
    with db.session() as session:
        assert validation.release(session, first, WORKER)  # handed back
    again = claim(db, settings)
    assert again.claim_number == first.claim_number

    later = Lease(VALIDATIONS, again, WORKER)
    verdicts = []
    running = threading.Thread(
        target=lambda: verdicts.append(VALIDATIONS.run(again, later, settings)), daemon=True
    )
    ours = {SANDBOX_LABEL: "1", **owner_labels(settings.storage.resolved_data_dir)}
    running.start()
    # The later run's intake sandbox, frozen so that it is certainly there when the earlier
    # run's hook looks for sandboxes to kill (SIGKILL ends a stopped process all the same).
    deadline = time.monotonic() + APPEAR_S
    while not (pids := labelled_pids(ours)) and time.monotonic() < deadline:
        time.sleep(POLL_S)
    assert pids, "the rerun's intake sandbox never appeared"
    for pid in pids:
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGSTOP)
    frozen = [pid for pid in pids if is_alive(pid)]  # not those that ended before the signal
    try:
        earlier.stop()  # what the stopping worker's heartbeat does with the earlier lease
        survivors = [pid for pid in frozen if is_alive(pid)]
    finally:
        for pid in frozen:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGCONT)
    running.join(timeout=APPEAR_S)
    assert frozen and survivors == frozen
    assert verdicts and verdicts[0].prepared is not None, verdicts
