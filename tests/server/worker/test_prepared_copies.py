"""A worker prepares each submission once into a folder named after its digest and never changes
it while the submission is in work; its warm agents are keyed by that digest, and the folder
goes only with them.

The reproduction: the worker kept 4 prepared submissions; when one was evicted and prepared again
into the same folder, its idle warm sandbox still bound the deleted files, and every later
episode was an ``agent_error`` charged to the team.
"""

from __future__ import annotations

import pytest

from arena.config import get_settings
from evaluator import sandbox
from evaluator.sandbox.warm_pool import WarmAgents, warm_agents
from server.worker import local
from submissions.intake.pack import pack_folder
from submissions.sample import sample_observation
from tests.server.live import export_settings

POLICY = """
class Policy:
    def act(self, obs):
        return {{k: [{value}.0, 0.0] for k in obs}}
"""


@pytest.fixture
def worker_env(settings, db, monkeypatch):
    """This process configured as a worker of the test's service (as ``arena worker`` is)."""
    export_settings(monkeypatch, settings)
    caches = (get_settings, local.database, local.store, local.sandbox_kind)
    for cache in caches:
        cache.cache_clear()
    yield get_settings()
    local.forget_finished(set(), set())
    for cache in caches:
        cache.cache_clear()


def upload(tmp_path, value: int) -> str:
    folder = tmp_path / f"agent{value}"
    folder.mkdir()
    (folder / "policy.py").write_text(POLICY.format(value=value))
    key = f"uploads/{value}/upload.zip"
    local.store().put(key, pack_folder(folder, tmp_path / f"agent{value}.zip"))
    return key


def act_once(pool: WarmAgents, submission, kind, settings) -> dict:
    with pool.lease(
        submission, kind, {}, settings.sandbox, settings.storage.resolved_data_dir
    ) as forked:
        assert forked is not None, "the submission should run warm"
        with forked.start() as handle:
            handle.reset()
            return handle.act(sample_observation())


def test_a_submission_prepared_again_gets_a_working_warm_agent(worker_env, tmp_path):
    settings = worker_env
    kind = sandbox.check_service_kind(None, settings.sandbox)
    keys = [upload(tmp_path, value) for value in range(6)]
    pool = warm_agents()  # the worker's own pool: the one that forgetting a submission closes
    try:
        first = local.prepared(keys[0])
        assert act_once(pool, first, kind, settings) == {"Agent_0": [0.0, 0.0]}
        for key in keys[1:]:  # more than the old cache of 4 kept: nothing in work is dropped
            local.prepared(key)
        assert local.prepared(keys[0]) is first and (first.root / "policy.py").is_file()
        # Its run ends: the folder goes, and the idle warm agent bound to it with it.
        local.forget_finished(set(keys[1:]), set())
        assert not first.root.exists()
        again = local.prepared(keys[0])  # a rerun: prepared again into the same content folder
        assert again.root == first.root and again.sha256 == first.sha256
        assert act_once(pool, again, kind, settings) == {"Agent_0": [0.0, 0.0]}
    finally:
        pool.close()


def test_two_uploads_of_one_zip_share_a_folder_that_stays_while_either_runs(worker_env, tmp_path):
    one = upload(tmp_path, 7)
    other = "uploads/8/upload.zip"
    local.store().put(other, tmp_path / "agent7.zip")  # the same bytes, another team's upload
    first, second = local.prepared(one), local.prepared(other)
    assert first.root == second.root
    local.forget_finished({other}, set())
    assert (second.root / "policy.py").is_file()
    local.forget_finished(set(), set())
    assert not second.root.exists()


def test_a_rerun_of_a_scored_submission_keeps_its_unpacked_zip(settings, db):
    """A re-run keeps showing the submission's score while it works: its zip was not 'in work',
    the reaper removed the prepared folder under the running episodes, and 10 of 39 ended
    ``FileNotFoundError: '/submission/policy.py'``, charged to the team."""
    from server.services import evaluation, submissions
    from tests.server.builders import make_team, seed_scored

    team_id, _ = make_team(db, "rerun")
    submission_id = seed_scored(db, team_id, (0.5, 100.0, 0.5, 0.5))
    with db.session() as session:
        evaluation.rerun(session, settings, submission_id)
    with db.read_session() as session:
        uploads, _ = submissions.keys_in_work(session)
        key = session.get(submissions.Submission, submission_id).upload_key
    assert key in uploads


def test_a_folder_left_half_removed_is_prepared_again(worker_env, tmp_path):
    """A removal cut short (a restart) left the digest's folder without its description: the
    next preparation renamed onto it (``OSError: [Errno 39] Directory not empty``), and one that
    kept its description but lost policy.py was run. Now a folder without its description is
    replaced, and removals are atomic (renamed aside first)."""
    key = upload(tmp_path, 9)
    ready = local.prepared(key)
    folder = ready.root.parent
    (folder / local.PREPARED_DESCRIPTION).unlink()  # what a cut-short removal leaves
    assert local.prepared(key).root == ready.root  # this process notices, too
    assert (ready.root / "policy.py").is_file()
    (folder / local.PREPARED_DESCRIPTION).unlink()
    local._prepared.clear()  # a restarted worker
    again = local.prepared(key)
    assert again.root == ready.root and (again.root / "policy.py").is_file()
    local.forget_finished(set(), set())
    assert not folder.exists() and not list(folder.parent.glob("trash-*"))
