"""A submission that will never run again frees its requirements' folder and the wheels only it
used, however it ended: cancelling it just after it was queued once kept its folder (3.2 GiB in
three rounds)."""

from __future__ import annotations

import json
from pathlib import Path

from sqlalchemy import update

from server.core.queue import TaskQueue
from server.models import Submission
from server.services import submissions
from server.worker.validations import free_requirements
from submissions.intake.dependencies import MANIFEST, deps_cache, wheel_store
from tests.server.builders import make_team, queued_submission


def installed(data_dir: Path, key: str, wheels: list[str]) -> Path:
    """A requirements folder as the intake leaves it: its manifest names its stored wheels."""
    for sha in wheels:
        (wheel_store(data_dir) / sha / "pkg").mkdir(parents=True, exist_ok=True)
    folder = deps_cache(data_dir) / key
    folder.mkdir(parents=True)
    manifest = {
        "wheels": [
            {"name": f"{s}.whl", "sha256": s, "bytes": 1, "unpacked_bytes": 1} for s in wheels
        ]
    }
    (folder / MANIFEST).write_text(json.dumps(manifest))
    return folder


def test_a_cancelled_submission_frees_its_requirements_at_once(db, settings) -> None:
    data_dir = settings.storage.resolved_data_dir
    team_id, _ = make_team(db, "alpha")
    kept = queued_submission(db, team_id)
    cancelled = queued_submission(db, team_id)
    with db.session() as session:
        for submission_id, key in ((kept, "kept"), (cancelled, "gone")):
            session.execute(
                update(Submission).where(Submission.id == submission_id).values(deps_key=key)
            )
    kept_folder = installed(data_dir, "kept", ["shared"])
    gone_folder = installed(data_dir, "gone", ["shared", "only-mine"])
    queue = TaskQueue(settings)
    try:
        submissions.cancel(db, queue, cancelled)
    finally:
        queue.close()
    # Freshly made (younger than any validation could take): freed all the same.
    assert free_requirements(db, settings.intake, data_dir) == 1
    assert kept_folder.is_dir() and not gone_folder.exists()
    assert sorted(p.name for p in wheel_store(data_dir).iterdir()) == ["shared"]
