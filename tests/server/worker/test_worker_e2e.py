"""End to end with real processes: an API, Celery workers on Redis, PostgreSQL, the bubblewrap
sandbox and the simulator. Uploads over HTTP, a worker killed with SIGKILL mid-evaluation, and a
Redis restart that loses every queued message."""

from __future__ import annotations

import signal
import socket
import subprocess
import time
import uuid
import zipfile
from datetime import timedelta
from pathlib import Path

import httpx
import numpy as np
import pytest
from sqlalchemy import func, select

from arena.config import ArtifactBackend, get_settings
from server.core.artifacts import artifact_store
from server.core.db import Database
from server.core.migrate import upgrade_database
from server.core.queue import TaskQueue
from server.models import ScenarioResult, Team, utcnow
from server.services import admin, validation
from sim.compiled import core_status
from tests.server.builders import bearer, make_team
from tests.server.conftest import REDIS_URL, _create_pg_database, _drop_pg_database
from tests.server.live import api_server, free_port, stop
from tests.server.service_stack import (
    SCENARIOS,
    build_small_suite,
    shared_dir,
    start_worker,
    upload_example,
    wait_finished,
)
from tests.settings import env_only, evaluate_args, with_fields

pytestmark = [pytest.mark.slow, pytest.mark.bwrap]


@pytest.fixture(scope="module")
def suite(tmp_path_factory):
    root = shared_dir("arena-e2e-suite-")
    yield build_small_suite(root)
    subprocess.run(["rm", "-rf", str(root)], check=False)


@pytest.fixture
def stack_settings(suite, broker_prefix):
    """PostgreSQL + Redis, as in production; a fresh database and key prefix per test."""
    name, url = _create_pg_database()
    upgrade_database(url)
    data = shared_dir("arena-e2e-data-")
    settings = env_only(
        storage={"data_dir": data, "database_url": url, "broker_url": REDIS_URL},
        service={
            "broker_key_prefix": f"{broker_prefix}{uuid.uuid4().hex[:6]}:",
            "lease_seconds": 8,
            "reaper_interval_s": 2,
            "daily_quota": 10,
        },
        suites={"hidden_suite_dir": suite, "public_suite_dir": suite},
        sandbox={"kind": "bubblewrap"},
        evaluation={"jobs": 2},
    )
    yield settings
    _drop_pg_database(name)
    subprocess.run(["rm", "-rf", str(data)], check=False)


def episode_processes(root: int) -> list[int]:
    """The simulator's episode processes below process ``root``: the children of its fork
    server (sim.episode_workers), which share its command line."""
    parents: dict[int, int] = {}
    forkservers = set()
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
            cmdline = (entry / "cmdline").read_bytes()
        except OSError:  # ended since the listing
            continue
        parents[int(entry.name)] = int(stat[stat.rindex(")") + 2 :].split()[1])
        if b"multiprocessing.forkserver" in cmdline:
            forkservers.add(int(entry.name))

    def below_root(pid: int) -> bool:
        while pid > 1:
            pid = parents.get(pid, 0)
            if pid == root:
                return True
        return False

    return [pid for pid in forkservers if parents[pid] in forkservers and below_root(pid)]


def results_per_scenario(db: Database) -> dict[str, int]:
    with db.session() as session:
        rows = session.execute(
            select(ScenarioResult.scenario_id, func.count()).group_by(ScenarioResult.scenario_id)
        )
        return dict(rows.all())


def test_three_examples_are_scored_and_ranked(stack_settings, tmp_path):
    db = Database(stack_settings.storage.database_url)
    tokens = {name: make_team(db, f"team-{name}")[1] for name in ("random", "keep_lane", "planner")}
    worker = start_worker(stack_settings, tmp_path / "worker.log")
    try:
        with api_server(stack_settings, tmp_path / "api.log") as (url, _):
            ids = {
                name: upload_example(url, token, name, tmp_path) for name, token in tokens.items()
            }
            final = {name: wait_finished(url, tokens[name], ids[name]) for name in ids}
            for name, body in final.items():
                assert body["status"] == "scored", (name, body)
                assert body["progress"] == {
                    "done": len(SCENARIOS),
                    "total": len(SCENARIOS),
                    "seeds": 1,
                    "unit": "episodes",
                }
            assert final["planner"]["metrics"]["completion"] == 0.0
            time.sleep(1.1)  # the API re-checks the leaderboard generation once a second
            board = httpx.get(f"{url}/api/v1/leaderboard").json()["entries"]
            assert [e["method_name"] for e in board] == ["planner", "keep_lane", "random"]
            # Failure reasons per family, for the owner; never a hidden scenario id.
            detail = httpx.get(
                f"{url}/api/v1/submissions/{ids['random']}", headers=bearer(tokens["random"])
            )
            assert detail.json()["failure_reasons"]
            logs = httpx.get(
                f"{url}/api/v1/submissions/{ids['random']}/logs", headers=bearer(tokens["random"])
            )
            assert not any(sid in detail.text + logs.text for sid in SCENARIOS)
            # Runs over: the submissions the worker unpacked leave its scratch within a round of
            # its reaper, while it keeps running.
            unpacked = stack_settings.storage.resolved_data_dir / "scratch"
            deadline = time.monotonic() + 30
            while any(unpacked.glob("*/submissions/*")) and time.monotonic() < deadline:
                time.sleep(0.5)
            assert not any(unpacked.glob("*/submissions/*")), list(unpacked.glob("*/*/*"))
            # ...and its simulator processes end (sim.episode_workers: not after their idle
            # time, 120 s).
            while episode_processes(worker.pid) and time.monotonic() < deadline:
                time.sleep(0.5)
            assert not episode_processes(worker.pid)
            assert worker.poll() is None
            # `arena admin status` asks the worker which per-step core its simulator runs.
            queue = TaskQueue(stack_settings)
            state = admin.service_status(db, stack_settings, queue)
            queue.close()
            assert state.worker_cores == {name: core_status() for name in state.workers or ()}
            assert len(state.worker_cores) == 1
    finally:
        stop(worker)
    assert set(results_per_scenario(db).values()) == {3}  # one row per submission and scenario
    db.dispose()
    # The worker's scratch (prepared submissions, validations, records) went with it: 1.9 GB
    # were once left behind.
    scratch = stack_settings.storage.resolved_data_dir / "scratch"
    assert not any(scratch.glob(f"{socket.gethostname()}-*")), list(scratch.iterdir())


def test_worker_killed_mid_evaluation_finishes_after_restart(stack_settings, tmp_path):
    db = Database(stack_settings.storage.database_url)
    _, token = make_team(db, "planner-team")
    worker = start_worker(stack_settings, tmp_path / "worker1.log", concurrency=1)
    try:
        with api_server(stack_settings, tmp_path / "api.log") as (url, _):
            sid = upload_example(url, token, "planner", tmp_path)
            # Wait until the worker holds a scenario (claimed, not finished), then kill it.
            wait_for_claims(db, lambda claims: len(claims) >= 1)
            stop(worker, signal.SIGKILL)
            worker = start_worker(stack_settings, tmp_path / "worker2.log", concurrency=2)
            body = wait_finished(url, token, sid)
            assert body["status"] == "scored"
            assert body["progress"]["done"] == len(SCENARIOS)
    finally:
        stop(worker)
    assert results_per_scenario(db) == dict.fromkeys(SCENARIOS, 1)
    db.dispose()


def wait_for_claims(db: Database, enough, timeout_s: float = 120) -> dict[str, str]:
    """Poll the scenarios held by a worker (claimed, not finished), scenario id -> worker,
    until ``enough(claims)``; returns them."""
    deadline = time.monotonic() + timeout_s
    while True:
        with db.session() as session:
            claims = dict(
                session.execute(
                    select(ScenarioResult.scenario_id, ScenarioResult.worker).where(
                        ScenarioResult.status == "running", ScenarioResult.worker != ""
                    )
                ).all()
            )
        if enough(claims):
            return claims
        assert time.monotonic() < deadline, f"scenarios held by workers: {claims}"
        time.sleep(0.2)


def sandboxes_of_run(run_id: int) -> list[int]:
    """Processes of bubblewrap sandboxes labelled with any claim of the run (server/worker
    labels them ``arena.run=r<run>a<claim>-<random>``)."""
    from evaluator.sandbox.subprocess_sandbox import LABELS_ENV, is_alive

    marker = f"arena.run=r{run_id}a".encode()
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            environ = (entry / "environ").read_bytes().split(b"\0")
        except OSError:
            continue
        labels = [v for v in environ if v.startswith(LABELS_ENV.encode() + b"=")]
        if labels and marker in labels[0] and is_alive(int(entry.name)):
            found.append(int(entry.name))
    return found


def test_a_worker_stopped_with_sigterm_hands_its_scenario_back(stack_settings, tmp_path):
    """SIGTERM mid-scenario: the episode is cut short, its claim released at once (no waiting
    for the lease) and its scenario re-sent; nothing is charged for the cut, no sandbox stays."""
    db = Database(stack_settings.storage.database_url)
    _, token = make_team(db, "planner-team")
    worker = start_worker(stack_settings, tmp_path / "worker1.log", concurrency=1)
    try:
        with api_server(stack_settings, tmp_path / "api.log") as (url, _):
            sid = upload_example(url, token, "planner", tmp_path)
            (claimed,) = wait_for_claims(db, lambda claims: len(claims) == 1)
            stopped_at = time.monotonic()
            worker.send_signal(signal.SIGTERM)  # the worker alone, as `arena up` dying does
            worker.wait(timeout=90)
            assert time.monotonic() - stopped_at < stack_settings.service.lease_seconds * 3
            with db.session() as session:
                row = session.scalar(
                    select(ScenarioResult).where(ScenarioResult.scenario_id == claimed)
                )
                assert row.status == "running" and row.worker == ""  # handed back, not charged
            # The stopping worker removed its agent's sandbox (only this run's are looked at:
            # other evaluations may run on this machine).
            assert not sandboxes_of_run(row.run_id)
            worker = start_worker(stack_settings, tmp_path / "worker2.log", concurrency=2)
            body = wait_finished(url, token, sid)
            assert body["status"] == "scored"
            assert body["metrics"]["completion"] == 0.0
    finally:
        stop(worker)
    assert results_per_scenario(db) == dict.fromkeys(SCENARIOS, 1)
    db.dispose()


def test_redis_restart_with_queued_submissions_loses_nothing(stack_settings, tmp_path):
    import redis  # here, not at the top: collecting the fast tier need not import it

    port = free_port()
    command = [
        "redis-server",
        "--port",
        str(port),
        "--bind",
        "127.0.0.1",
        "--save",
        "",
        "--appendonly",
        "no",
    ]
    redis_server = subprocess.Popen(command, stdout=subprocess.DEVNULL, start_new_session=True)
    settings = with_fields(
        stack_settings,
        storage={"broker_url": f"redis://127.0.0.1:{port}/0"},
        service={"broker_key_prefix": ""},
    )
    db = Database(settings.storage.database_url)
    # Two teams: a team has one upload validating at a time.
    tokens = {name: make_team(db, f"restart-{name}")[1] for name in ("keep_lane", "random")}
    worker = None
    try:
        _wait_redis(port)
        with api_server(settings, tmp_path / "api.log") as (url, _):
            ids = {
                name: upload_example(url, token, name, tmp_path) for name, token in tokens.items()
            }
            assert redis.Redis(port=port).llen("arena") == 2  # queued, not yet taken
            # Restart Redis without persistence: the queued messages are gone.
            stop(redis_server)
            redis_server = subprocess.Popen(
                command, stdout=subprocess.DEVNULL, start_new_session=True
            )
            _wait_redis(port)
            assert redis.Redis(port=port).llen("arena") == 0
            worker = start_worker(settings, tmp_path / "worker.log")
            for name, sid in ids.items():
                assert wait_finished(url, tokens[name], sid)["status"] == "scored"
    finally:
        if worker is not None:
            stop(worker)
        stop(redis_server)
    db.dispose()


def _wait_redis(port: int) -> None:
    import redis

    for _ in range(100):
        try:
            if redis.Redis(port=port).ping():
                return
        except redis.ConnectionError:
            time.sleep(0.1)
    raise RuntimeError("redis-server did not start")


def test_cancel_while_running_stops_the_evaluation_and_the_worker_goes_on(stack_settings, tmp_path):
    db = Database(stack_settings.storage.database_url)
    _, token = make_team(db, "cancel-team")
    worker = start_worker(stack_settings, tmp_path / "worker.log", concurrency=1)
    try:
        with api_server(stack_settings, tmp_path / "api.log") as (url, _):
            sid = upload_example(url, token, "planner", tmp_path)
            deadline = time.monotonic() + 120
            while (
                httpx.get(f"{url}/api/v1/submissions/{sid}", headers=bearer(token)).json()["status"]
                != "running"
            ):
                assert time.monotonic() < deadline
                time.sleep(0.2)
            cancelled = httpx.post(f"{url}/api/v1/submissions/{sid}/cancel", headers=bearer(token))
            assert cancelled.status_code == 200 and cancelled.json()["status"] == "cancelled"
            # The same worker evaluates the next submission to the end...
            other = upload_example(url, token, "keep_lane", tmp_path)
            assert wait_finished(url, token, other)["status"] == "scored"
            # ...and the cancelled one stayed cancelled, short of its scenarios.
            body = httpx.get(f"{url}/api/v1/submissions/{sid}", headers=bearer(token)).json()
            assert body["status"] == "cancelled"
            assert body["progress"]["done"] < len(SCENARIOS)
            assert body["metrics"] is None
    finally:
        stop(worker)
    # Sandboxes of this test mount its data folder; none may outlive the worker.
    leftovers = subprocess.run(
        ["pgrep", "-f", str(stack_settings.storage.data_dir)], capture_output=True, text=True
    )
    assert leftovers.stdout.strip() == "", "a sandbox outlived the cancelled evaluation"
    db.dispose()


def test_local_evaluation_and_the_service_agree(stack_settings, suite, tmp_path):
    """One evaluation core: `arena evaluate` and the worker + database give the same metrics,
    per-family figures and scenario statuses for the same submission and scenarios."""
    from evaluator.runner import EvaluationRequest, evaluate
    from server.core.db import Database
    from tests.server.builders import pack_example

    local = evaluate(
        EvaluationRequest(
            pack_example("keep_lane", tmp_path),
            suite,
            out_dir=tmp_path / "local",
            jobs=2,
            sandbox="bubblewrap",
        ),
        **evaluate_args(get_settings()),
    )
    db = Database(stack_settings.storage.database_url)
    _, token = make_team(db, "keep-lane-team")
    worker = start_worker(stack_settings, tmp_path / "worker.log")
    try:
        with api_server(stack_settings, tmp_path / "api.log") as (url, _):
            sid = upload_example(url, token, "keep_lane", tmp_path)
            body = wait_finished(url, token, sid)
    finally:
        stop(worker)
    assert body["status"] == "scored", body
    assert body["metrics"] == local.metrics.model_dump()
    for family, metrics in local.families.items():
        assert {k: v for k, v in body["families"][family].items() if k != "scenarios"} == (
            metrics.model_dump()
        )
    with db.session() as session:
        stored = dict(
            session.execute(select(ScenarioResult.scenario_id, ScenarioResult.status)).all()
        )
    assert stored == {entry.id: entry.status for entry in local.scenarios}
    assert any(entry.agents[0].reason != "reached_goal" for entry in local.scenarios)
    db.dispose()


def test_two_workers_with_separate_data_folders_share_nothing_but_broker_and_database(
    stack_settings, tmp_path
):
    """Uploads and records go through the database artifact store: two workers on "two
    machines" (separate data folders) evaluate one submission together; one is killed mid-run
    and the other finishes it; no scenario is counted twice."""
    from server.core.artifacts import DatabaseStore

    def machine(name: str):
        folder = shared_dir(f"arena-e2e-{name}-")
        return with_fields(
            stack_settings, storage={"data_dir": folder, "artifact_store": ArtifactBackend.database}
        )

    api_settings, first, second = machine("api"), machine("w1"), machine("w2")
    db = Database(stack_settings.storage.database_url)
    _, token = make_team(db, "planner-team")
    workers = [
        start_worker(first, tmp_path / "w1.log", concurrency=1),
        start_worker(second, tmp_path / "w2.log", concurrency=1),
    ]
    try:
        with api_server(api_settings, tmp_path / "api.log") as (url, _):
            sid = upload_example(url, token, "planner", tmp_path)
            # Both workers hold a scenario: the run is shared.
            wait_for_claims(db, lambda claims: len(set(claims.values())) == 2)
            stop(workers[0], signal.SIGKILL)
            body = wait_finished(url, token, sid, timeout_s=300)
            assert body["status"] == "scored", body
            assert body["metrics"]["completion"] == 0.0
    finally:
        for worker in workers:
            stop(worker)
    assert results_per_scenario(db) == dict.fromkeys(SCENARIOS, 1)
    store = DatabaseStore(db)
    with db.session() as session:
        keys = list(session.scalars(select(ScenarioResult.record_key)))
    assert keys and all(store.exists(key) for key in keys if key)
    for settings in (api_settings, first, second):  # nothing of the run on any machine's disk
        assert not list(settings.storage.data_dir.rglob("*.npz"))
        subprocess.run(["rm", "-rf", str(settings.storage.data_dir)], check=False)
    db.dispose()


def test_several_episodes_per_scenario_through_the_worker(stack_settings, suite, tmp_path):
    """A phase running 2 episodes of each reactive scenario: the worker claims each episode on
    its own (the replay runs once), the score and its completion interval are the local
    evaluation's with --episodes 2, and the leaderboard page shows the interval."""
    from evaluator.runner import EvaluationRequest, evaluate
    from evaluator.runner.results import stored_episodes
    from server.services import phases
    from tests.server.builders import pack_example

    local = evaluate(
        EvaluationRequest(
            pack_example("keep_lane", tmp_path),
            suite,
            out_dir=tmp_path / "local",
            jobs=2,
            sandbox="bubblewrap",
            episodes_per_scenario=2,
        ),
        **evaluate_args(get_settings()),
    )
    interval = local.completion_interval()
    db = Database(stack_settings.storage.database_url)
    phases.set_phase(db, stack_settings, "final", phases.PhaseChanges(episodes_per_scenario=2))
    _, token = make_team(db, "keep-lane-team")
    worker = start_worker(stack_settings, tmp_path / "worker.log")
    try:
        with api_server(stack_settings, tmp_path / "api.log") as (url, _):
            sid = upload_example(url, token, "keep_lane", tmp_path)
            body = wait_finished(url, token, sid)
            time.sleep(1.1)  # the API re-checks the leaderboard generation once a second
            page = httpx.get(f"{url}/?phase=final").text
            entry = httpx.get(f"{url}/api/v1/leaderboard").json()["entries"][0]
    finally:
        stop(worker)
    reactive = [s for s in SCENARIOS if "replay" not in s]
    assert body["status"] == "scored", body
    episodes = 2 * len(reactive) + 1
    assert body["progress"] == {
        "done": episodes,
        "total": episodes,
        "seeds": 1,
        "unit": "episodes",
    }
    assert body["episodes_per_scenario"] == 2
    assert body["metrics"] == local.metrics.model_dump()
    assert body["completion_interval"] == {"low": interval.low, "high": interval.high}
    assert entry["completion_interval"] == body["completion_interval"]
    assert f"[{interval.low:.4f}, {interval.high:.4f}]" in page
    with db.session() as session:
        rows = session.execute(
            select(ScenarioResult.scenario_id, ScenarioResult.episode, ScenarioResult.status)
        ).all()
    assert sorted((sid, k) for sid, k, _ in rows) == sorted(
        [(s, k) for s in reactive for k in (0, 1)] + [("p030_replay_cruise", 0)]
    )
    assert {(sid, k): status for sid, k, status in rows} == {
        (key.scenario_id, key.index): episode.status
        for scenario in local.scenarios
        for key, episode in stored_episodes(scenario)
    }
    db.dispose()


def test_adaptive_rounds_through_the_worker_match_a_fixed_evaluation(
    stack_settings, suite, tmp_path
):
    """An adaptive phase whose target is never met: the worker's aggregation sends rounds of one
    episode per reactive scenario up to the cap, and the score is exactly the local evaluation's
    with that many episodes (same seeds, same results)."""
    from evaluator.runner import EvaluationRequest, evaluate
    from server.models import EvaluationRun
    from server.services import phases
    from tests.server.builders import pack_example

    local = evaluate(
        EvaluationRequest(
            pack_example("keep_lane", tmp_path),
            suite,
            out_dir=tmp_path / "local",
            jobs=2,
            sandbox="bubblewrap",
            episodes_per_scenario=3,
        ),
        **evaluate_args(get_settings()),
    )
    db = Database(stack_settings.storage.database_url)
    changes = phases.PhaseChanges(episodes_per_scenario=1, adaptive_target=1e-6, max_episodes=3)
    phases.set_phase(db, stack_settings, "final", changes)
    _, token = make_team(db, "adaptive-team")
    worker = start_worker(stack_settings, tmp_path / "worker.log")
    try:
        with api_server(stack_settings, tmp_path / "api.log") as (url, _):
            sid = upload_example(url, token, "keep_lane", tmp_path)
            body = wait_finished(url, token, sid)
    finally:
        stop(worker)
    reactive = [s for s in SCENARIOS if "replay" not in s]
    assert body["status"] == "scored", body
    assert body["episodes_per_scenario"] == 3
    assert body["progress"]["total"] == 3 * len(reactive) + 1
    assert body["metrics"] == local.metrics.model_dump()
    with db.session() as session:
        (run,) = session.scalars(select(EvaluationRun)).all()
        assert (run.episode_round, run.max_episodes) == (1, 3)
    db.dispose()


def test_audit_reruns_a_score_bit_identically_and_names_what_differs(
    stack_settings, tmp_path, monkeypatch
):
    """`arena admin audit`: a score the worker made re-runs bit-identically from its manifest;
    a manifest naming other software is refused, component named; a stored record that no
    longer matches is reported as the first differing record."""
    from arena.config import get_settings
    from arena_command import app
    from server.models import Score
    from tests.cli_runner import CliRunner

    db = Database(stack_settings.storage.database_url)
    _, token = make_team(db, "auditors")
    worker = start_worker(stack_settings, tmp_path / "worker.log")
    try:
        with api_server(stack_settings, tmp_path / "api.log") as (url, _):
            sid = upload_example(url, token, "keep_lane", tmp_path)
            assert wait_finished(url, token, sid)["status"] == "scored"
    finally:
        stop(worker)
    for group, name in (
        ("storage", "data_dir"),
        ("storage", "database_url"),
        ("storage", "broker_url"),
        ("service", "broker_key_prefix"),
        ("suites", "hidden_suite_dir"),
        ("suites", "public_suite_dir"),
        ("sandbox", "kind"),
    ):
        fields = getattr(stack_settings, group)
        variable = fields.env_names()[name]
        monkeypatch.setenv(variable, str(getattr(fields, name)))
    get_settings.cache_clear()
    runner = CliRunner()

    def audit(*args):
        return runner.invoke(app, ["admin", "audit", *args])

    try:
        same = audit(str(sid))
        assert same.exit_code == 0, same.output
        assert f"submission {sid}: bit-identical ({len(SCENARIOS)} episodes)" in same.stdout
        # Piped, the progress goes to stderr as plain lines (never a silent pipe for minutes).
        assert same.stderr.startswith(f"auditing 1 submission(s): {sid}\n")
        done = len(SCENARIOS)
        assert f"submission {sid}: {done}/{done} episodes re-run" in same.stderr
        assert "re-run" not in same.stdout
        sampled = audit("--sample", "5")
        assert sampled.exit_code == 0 and "bit-identical" in sampled.output, sampled.output

        with db.session() as session:
            score = session.scalar(select(Score))
            original = score.manifest
            environment = dict(original["environments"][0], sumo="0.0.1")
            score.manifest = dict(original, environments=[environment])
        refused = audit(str(sid))
        assert refused.exit_code == 1
        assert "refused" in refused.output and "environment.sumo" in refused.output
        assert "-> 1." in refused.output  # what runs here, next to what the score ran with

        with db.session() as session:
            session.scalar(select(Score)).manifest = original
            first = session.scalar(
                select(ScenarioResult)
                .where(ScenarioResult.record_key.is_not(None))
                .order_by(ScenarioResult.scenario_id)
            )
            key = first.record_key
        store = artifact_store(stack_settings.storage, db)
        altered = tmp_path / "altered.npz"
        with np.load(store.fetch(key, tmp_path / "stored.npz")) as record:
            arrays = {name: record[name] for name in record.files}
        field = next(n for n, a in arrays.items() if a.dtype.kind == "f" and a.size)
        arrays[field] = arrays[field].copy()
        arrays[field].flat[0] += 1.0
        np.savez(altered, **arrays)
        store.put(key, altered)
        differs = audit(str(sid))
        assert differs.exit_code == 1
        assert f"differs after 1 episode(s): {first.scenario_id}: record array '{field}'" in (
            " ".join(differs.output.split())
        )
    finally:
        get_settings.cache_clear()
    db.dispose()


def restart(stack_settings, tmp_path: Path, worker: subprocess.Popen, n: int):
    """The whole service stops (SIGTERM) and starts again: a new worker process, new scratch."""
    stop(worker)
    return start_worker(stack_settings, tmp_path / f"worker-{n}.log")


def attempt_results(db: Database, sid: int, attempt: int) -> list[tuple]:
    """(scenario, episode, status, reason, steps) of one attempt's episodes."""
    from server.models import EvaluationRun

    with db.session() as session:
        rows = session.execute(
            select(
                ScenarioResult.scenario_id,
                ScenarioResult.episode,
                ScenarioResult.status,
                ScenarioResult.reason,
                ScenarioResult.steps,
            )
            .join(EvaluationRun, EvaluationRun.id == ScenarioResult.run_id)
            .where(EvaluationRun.submission_id == sid, EvaluationRun.attempt == attempt)
        ).all()
    return sorted(tuple(row) for row in rows)


@pytest.mark.parametrize(
    "kind",
    [pytest.param("bubblewrap", id="bubblewrap"), pytest.param("docker", marks=pytest.mark.docker)],
)
@pytest.mark.parametrize("example", ["keep_lane", "ppo"])  # ppo: a requirements.txt
def test_organiser_actions_after_a_restart(stack_settings, tmp_path, kind, example):
    """The service restarts between the upload and each action. A re-run of the PPO example
    (requirements) after a restart ended scored with 10/39 episodes FileNotFoundError
    '/submission/policy.py' (its prepared folder removed under it) or ENOTEMPTY: now every
    action works, a re-run reproduces the first attempt exactly and nothing of ours is shown
    as the team's."""
    from server.core.queue import TaskQueue
    from server.services import admin, phases, submissions
    from server.services.audit import audit
    from server.services.errors import Conflict
    from server.services.release import release_phase

    settings = with_fields(stack_settings, sandbox={"kind": kind})
    db = Database(settings.storage.database_url)
    queue = TaskQueue(settings)
    _, token = make_team(db, "restarted")
    worker = start_worker(settings, tmp_path / "worker-0.log")
    try:
        with api_server(settings, tmp_path / "api-0.log") as (url, _):
            sid = upload_example(url, token, example, tmp_path)
            first = wait_finished(url, token, sid, timeout_s=900)
        assert first["status"] == "scored", first
        worker = restart(settings, tmp_path, worker, 1)
        with api_server(settings, tmp_path / "api-1.log") as (url, _):
            assert admin.rerun(db, settings, queue, sid) == 2
            deadline = time.monotonic() + 900
            while True:
                body = httpx.get(
                    f"{url}/api/v1/submissions/{sid}", headers=bearer(token), timeout=10
                ).json()
                if body["latest_attempt"]["status"] not in ("queued", "running"):
                    break
                assert time.monotonic() < deadline, body
                time.sleep(1)
            assert body["latest_attempt"] == {"attempt": 2, "status": "scored", "error": ""}
            assert body["attempt"] == 2 and body["metrics"] == first["metrics"]
        assert attempt_results(db, sid, 2) == attempt_results(db, sid, 1)
        worker = restart(settings, tmp_path, worker, 2)
        with pytest.raises(Conflict):  # nothing is lost: nothing to re-send
            admin.requeue(db, settings, queue, sid)
        with db.session() as session:
            run_id = submissions.current_run(session.get(submissions.Submission, sid)).id
        profile, metrics = admin.rescore_run(
            db, settings.evaluation, artifact_store(settings.storage, db), run_id
        )
        assert metrics["completion"] == first["metrics"]["completion"], profile
        report = audit(db, artifact_store(settings.storage, db), sid, **evaluate_args(settings))
        assert report.identical, report
        with api_server(settings, tmp_path / "api-2.log") as (url, _):
            other = upload_example(url, token, example, tmp_path)
            worker = restart(settings, tmp_path, worker, 3)
            assert submissions.cancel(db, queue, other).status == "cancelled"
            assert wait_finished(url, token, other)["status"] == "cancelled"
        worker = restart(settings, tmp_path, worker, 4)
        with db.session() as session:
            phase = session.get(submissions.Submission, sid).phase
        changes = phases.PhaseChanges(ends_at=utcnow() - timedelta(minutes=1))
        phases.set_phase(db, settings, phase, changes)
        assert release_phase(db, phase).released_at is not None
        with api_server(settings, tmp_path / "api-3.log") as (url, _):
            suite = httpx.get(
                f"{url}/api/v1/scenarios/released/{phase}.zip", headers=bearer(token), timeout=30
            )
            assert suite.status_code == 200 and suite.content[:2] == b"PK"
            scenario = attempt_results(db, sid, 2)[0][0]
            replay = httpx.get(
                f"{url}/api/v1/submissions/{sid}/replays/{scenario}",
                headers=bearer(token),
                timeout=30,
            )
            assert replay.status_code == 200, replay.text
    finally:
        stop(worker)
    db.dispose()


def long_validation_zip(path: Path, files: int) -> Path:
    """A zip whose validation takes long: ``files`` one-MiB Python files (each a run of one
    statement: the zip stays small), rejected at the end (no Policy class)."""
    body = (b"x = 0\n" * (1024**2 // 6))[: 1024**2]
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED) as archive:
        archive.writestr("policy.py", "class Agent:\n    pass\n")
        for number in range(files):
            archive.writestr(f"lib/m{number:03d}.py", body)
    return path


def test_a_long_validation_yields_its_worker_to_another_teams_upload(stack_settings, tmp_path):
    """Issue 40: one team's long validation held the only worker and another team's upload
    waited behind it. Now, past its slice, it yields to the team that used less validation time:
    the other team's upload is judged first, and the long one still ends, charged to its team."""
    settings = with_fields(stack_settings, intake={"validation_slice_s": 1.0})
    db = Database(settings.storage.database_url)
    _, slow_token = make_team(db, "slow-team")
    _, other_token = make_team(db, "other-team")
    worker = start_worker(settings, tmp_path / "worker.log", concurrency=1)
    try:
        with api_server(settings, tmp_path / "api.log") as (url, _):
            slow_zip = long_validation_zip(tmp_path / "slow.zip", 300)
            with slow_zip.open("rb") as handle:
                slow = httpx.post(
                    f"{url}/api/v1/submissions",
                    headers=bearer(slow_token),
                    data={"track": "freestyle", "method_name": "slow"},
                    files={"file": ("slow.zip", handle, "application/zip")},
                    timeout=120,
                ).json()["id"]
            time.sleep(2.0)  # the slow validation holds the worker by now
            other = upload_example(url, other_token, "keep_lane", tmp_path)
            seen = []
            deadline = time.monotonic() + 600
            while len(seen) < 2 and time.monotonic() < deadline:
                for token, sid in ((slow_token, slow), (other_token, other)):
                    status = httpx.get(
                        f"{url}/api/v1/submissions/{sid}", headers=bearer(token), timeout=10
                    ).json()["status"]
                    if status != "validating" and sid not in seen:
                        seen.append(sid)
                time.sleep(0.5)
            assert seen == [other, slow], "the other team's upload waited for the long one"
    finally:
        stop(worker)
    with db.read_session() as session:
        slow_team = session.scalar(select(Team.id).where(Team.name == "slow-team"))
        charged = validation.used_today(session, slow_team, utcnow())
    assert charged > settings.intake.validation_slice_s
    db.dispose()
