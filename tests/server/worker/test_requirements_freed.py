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
from server.worker.validations import free_requirements, team_share_exceeded
from submissions.intake.dependencies import MANIFEST, deps_cache, wheel_store
from tests.server.builders import make_team, queued_submission
from tests.settings import with_fields


def installed(data_dir: Path, key: str, wheels: list[str], unpacked_bytes: int = 1) -> Path:
    """A requirements folder as the intake leaves it: its manifest names its stored wheels."""
    for sha in wheels:
        (wheel_store(data_dir) / sha / "pkg").mkdir(parents=True, exist_ok=True)
    folder = deps_cache(data_dir) / key
    folder.mkdir(parents=True)
    manifest = {
        "wheels": [
            {"name": f"{s}.whl", "sha256": s, "bytes": 1, "unpacked_bytes": unpacked_bytes}
            for s in wheels
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


def test_a_team_is_charged_only_for_the_wheels_no_other_team_uses(db, settings) -> None:
    data_dir = settings.storage.resolved_data_dir
    intake = with_fields(settings, intake={"max_team_deps_bytes": 150}).intake
    alpha, _ = make_team(db, "alpha")
    beta, _ = make_team(db, "beta")
    theirs = queued_submission(db, beta)
    ours = queued_submission(db, alpha)
    with db.session() as session:
        session.execute(update(Submission).where(Submission.id == theirs).values(deps_key="b"))
    installed(data_dir, "b", ["shared"], unpacked_bytes=100)
    installed(data_dir, "a", ["shared", "mine"], unpacked_bytes=100)
    # 100 bytes of its own (the shared wheel is beta's too): within 150.
    assert team_share_exceeded(db, intake, data_dir, ours, "a") is None
    installed(data_dir, "a2", ["shared", "mine", "also-mine"], unpacked_bytes=100)
    refused = team_share_exceeded(db, intake, data_dir, ours, "a2")
    assert refused is not None and "[rule: team-deps-bytes]" in refused
