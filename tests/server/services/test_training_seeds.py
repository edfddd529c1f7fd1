"""Track 2 over seeds, through the service as the worker's tasks drive it (on SQLite and
PostgreSQL): a phase of N training seeds trains each offline submission N times, each model
evaluated by its own run; the submission is scored over the seeds once the last one is, a seed's
failure through the team's fault fails it naming the seed, a seed lost on our side waits for a
requeue while the others go on, failure counts and the manifest cover every seed, compare puts
seed sets side by side, and the organisers' operations act on the whole set."""

from __future__ import annotations

import dataclasses
import io
import json
import zipfile

import pytest
from sqlalchemy import select

from arena.outcome import ScenarioStatus
from evaluator.runner import ScenarioOutcome
from server.core.artifacts import DatabaseStore
from server.core.queue import TaskQueue
from server.models import EvaluationRun, Phase, SeedSetScore, Submission, TrainingJob, Visibility
from server.services import (
    admin,
    evaluation,
    leaderboard,
    phases,
    seed_sets,
    submissions,
    training,
)
from server.services.errors import InvalidInput
from server.status import RunStatus, SubmissionStatus, TrainingStatus
from server.tracks import Track
from tests.server.builders import (
    bearer,
    claim_episode,
    make_team,
    queued_submission,
    report_episode,
)
from tests.server.conftest import ADMIN_TOKEN


def set_seeds(db, settings, seeds: int) -> None:
    phases.set_phase(db, settings, "final", phases.PhaseChanges(training_seeds=seeds))


def offline(db, team: str = "bc") -> int:
    team_id, _ = make_team(db, team)
    return queued_submission(db, team_id, track=Track.offline)


def start(db, settings, submission_id: int) -> tuple[int, ...]:
    with db.session() as session:
        return training.start_training(session, settings.service, submission_id)


def claim(db, settings, training_id: int):
    with db.session() as session:
        return training.claim_training(session, settings.service, training_id, "w1")


def trained(db, settings, job, model_sha256: str | None = None):
    with db.session() as session:
        return training.record_trained(
            session,
            settings,
            job,
            "w1",
            elapsed_s=1.0,
            log_tail="saved",
            model_key=f"training/{job.training_id}/model.tar.gz",
            # Each seed's model its own digest unless given.
            model_sha256=model_sha256 or f"{job.training_id:064x}",
            model_size=10,
        )


def evaluate(db, settings, plan, fails: int) -> RunStatus | None:
    """Every episode of the run reported as a worker does, the first ``fails`` scenarios with
    the agent colliding; then the aggregation."""
    for number, episode in enumerate(plan.episodes):
        report_episode(db, settings, plan, episode, reached_goal=number >= fails)
    with db.session() as session:
        return evaluation.finish_run(session, DatabaseStore(db), plan.run_id)


def status_of(db, submission_id: int) -> SubmissionStatus:
    with db.session() as session:
        return session.get(Submission, submission_id).status


def test_each_seed_is_a_training_job_of_its_own_with_its_seed(db, settings):
    set_seeds(db, settings, 3)
    sid = offline(db)
    ids = start(db, settings, sid)
    assert len(ids) == 3
    claims = [claim(db, settings, training_id) for training_id in ids]
    assert [c.seed for c in claims] == [0, 1, 2]  # ARENA_TRAIN_SEED of each sandbox
    with db.read_session() as session:
        jobs = session.scalars(select(TrainingJob).order_by(TrainingJob.seed)).all()
        assert {(j.seed_set, j.seeds) for j in jobs} == {(1, 3)}
    assert start(db, settings, sid) == ()  # a duplicate delivery


def test_the_submission_is_scored_over_its_seeds_once_the_last_one_is(db, settings):
    set_seeds(db, settings, 3)
    sid = offline(db)
    plans = [trained(db, settings, claim(db, settings, i)) for i in start(db, settings, sid)]
    scenarios = len({episode.scenario_id for episode in plans[0].episodes})
    # Seed 0 fails no scenario, seed 1 one, seed 2 two.
    assert evaluate(db, settings, plans[0], fails=0) == RunStatus.scored
    assert evaluate(db, settings, plans[1], fails=1) == RunStatus.scored
    assert status_of(db, sid) == SubmissionStatus.running  # a seed still to come
    with db.read_session() as session:
        assert leaderboard.compute(session, Track.offline, "final").entries == []
    assert evaluate(db, settings, plans[2], fails=2) == RunStatus.scored
    assert status_of(db, sid) == SubmissionStatus.scored
    per_seed = [0.0, 1 / scenarios, 2 / scenarios]
    with db.read_session() as session:
        score = session.scalar(select(SeedSetScore))
        assert score.completion == pytest.approx(sum(per_seed) / 3)
        assert (score.seed_completion_min, score.seed_completion_max) == pytest.approx(
            (0.0, 2 / scenarios)
        )
        assert score.seed_completion_std == pytest.approx(1 / scenarios)
        assert score.completion_low <= score.completion <= score.completion_high
        view = submissions.detail(session, session.get(Submission, sid))
        board = leaderboard.compute(session, Track.offline, "final")
    assert view.metrics.completion == pytest.approx(score.completion)
    assert view.seeds.count == 3
    assert [s.completion for s in view.seeds.per_seed] == pytest.approx(per_seed)
    assert view.completion_interval.low == score.completion_low
    (entry,) = board.entries
    assert entry.metrics.completion == pytest.approx(score.completion)
    assert entry.seeds.completion_max == pytest.approx(2 / scenarios)
    assert entry.rank_range == "1"
    rows = leaderboard.to_csv(board).splitlines()
    header, row = rows[0].split(","), rows[1].split(",")
    assert row[header.index("seeds")] == "3"
    assert float(row[header.index("seed_completion_max")]) == pytest.approx(2 / scenarios)


def test_the_rest_api_shows_the_seeds(db, settings, client):
    set_seeds(db, settings, 2)
    team_id, token = make_team(db, "api")
    sid = queued_submission(db, team_id, track=Track.offline)
    for training_id in start(db, settings, sid):
        evaluate(db, settings, trained(db, settings, claim(db, settings, training_id)), fails=1)
    shown = client.get(f"/api/v1/submissions/{sid}", headers={"Authorization": f"Bearer {token}"})
    assert shown.status_code == 200, shown.text
    seeds = shown.json()["seeds"]
    assert (seeds["count"], seeds["completion_std"]) == (2, 0.0)
    assert [s["seed"] for s in seeds["per_seed"]] == [0, 1]
    board = client.get("/api/v1/leaderboard", params={"track": "offline", "phase": "final"})
    (entry,) = board.json()["entries"]
    assert entry["seeds"]["count"] == 2
    assert entry["completion_interval"] == shown.json()["completion_interval"]
    csv = client.get("/api/v1/leaderboard.csv", params={"track": "offline", "phase": "final"})
    assert "seed_completion_std" in csv.text.splitlines()[0]
    page = client.get("/", params={"track": "offline", "phase": "final"})
    assert "2 seeds" in page.text
    submit = client.get("/submit")  # said before the upload
    assert "offline submissions train 2 times" in submit.text


def test_seeds_that_trained_byte_identical_models_are_called_out_not_a_spread_of_0(
    db, settings, client, arena
):
    """train.py ignored ARENA_TRAIN_SEED: the page once showed "std 0.0000" for two seeds."""
    set_seeds(db, settings, 3)
    team_id, token = make_team(db, "same")
    sid = queued_submission(db, team_id, track=Track.offline)
    for training_id in start(db, settings, sid):
        plan = trained(db, settings, claim(db, settings, training_id), model_sha256="ab" * 32)
        evaluate(db, settings, plan, fails=1)
    seeds = client.get(f"/api/v1/submissions/{sid}", headers=bearer(token)).json()["seeds"]
    assert seeds["identical_models"] == [[0, 1, 2]]
    assert seeds["ignores_seed"].startswith(
        "train.py ignores the seed: every seed trained byte-identical models"
    )
    page = client.get("/", params={"track": "offline", "phase": "final"}).text
    assert "3 seeds: train.py ignores the seed" in page and "std 0.0000" not in page
    shown = arena("submissions", "show", str(sid))
    assert "train.py ignores the seed" in shown
    # Each seed's evaluation is a run of its own: numbered, and said to be that seed's.
    assert "attempt 2 (seed 1 of 3): scored" in shown
    # Seeds of their own models: nothing said.
    other_team, other_token = make_team(db, "own")
    other = queued_submission(db, other_team, track=Track.offline)
    for training_id in start(db, settings, other):
        evaluate(db, settings, trained(db, settings, claim(db, settings, training_id)), fails=1)
    shown = client.get(f"/api/v1/submissions/{other}", headers=bearer(other_token)).json()
    assert (shown["seeds"]["identical_models"], shown["seeds"]["ignores_seed"]) == ([], "")


def test_progress_and_agent_cpu_count_every_seeds_run(db, settings, client):
    set_seeds(db, settings, 3)
    phases.set_phase(db, settings, "final", phases.PhaseChanges(visibility=Visibility.full))
    team_id, token = make_team(db, "progress")
    sid = queued_submission(db, team_id, track=Track.offline)
    jobs = [claim(db, settings, training_id) for training_id in start(db, settings, sid)]
    plans = [trained(db, settings, job) for job in jobs[:2]]  # seed 2 still trains
    episodes = len(plans[0].episodes)
    report_episode(db, settings, plans[0], plans[0].episodes[0], reached_goal=True, agent_cpu_s=1.5)
    for episode in plans[1].episodes:
        report_episode(db, settings, plans[1], episode, reached_goal=True, agent_cpu_s=2.0)
    shown = client.get(f"/api/v1/submissions/{sid}", headers={"Authorization": f"Bearer {token}"})
    assert shown.status_code == 200, shown.text
    body = shown.json()
    # Seed 2's run is yet to come: its episodes are counted in the total.
    assert body["progress"] == {
        "done": 1 + episodes,
        "total": 3 * episodes,
        "seeds": 3,
        "unit": "episodes",
    }
    assert body["agent_cpu"]["used_s"] == pytest.approx(1.5 + 2.0 * episodes)
    assert body["agent_cpu"]["most_used_s"] == pytest.approx(2.0 * episodes)
    assert body["agent_cpu"]["evaluations"] == 2
    (listed,) = client.get(
        "/api/v1/submissions", headers={"Authorization": f"Bearer {token}"}
    ).json()
    assert listed["progress"] == body["progress"]


def test_a_seeds_failure_fails_the_submission_naming_it_and_stops_the_others(db, settings):
    set_seeds(db, settings, 3)
    sid = offline(db)
    ids = start(db, settings, sid)
    first, second, third = (claim(db, settings, i) for i in ids)
    plan = trained(db, settings, first)  # seed 0 trained: its evaluation starts
    with db.session() as session:
        assert training.record_failed(
            session, second, "w1", failure="train_crashed", error="exit 1", log_tail="boom"
        )
    with db.read_session() as session:
        submission = session.get(Submission, sid)
        assert submission.status == SubmissionStatus.failed
        # What failed, where to read why, and what to do about it.
        assert submission.status_reason.startswith("seed 1 (of 3): train_crashed: exit 1. ")
        assert "training log is shown with the training (seed 1)" in submission.status_reason
        assert "every ARENA_TRAIN_SEED from 0 to 2: fix it" in submission.status_reason
        assert not submission.failed_on_our_side  # charged: the team's train.py
        # Nothing of the set is left to run: every job and run is over.
        assert {job.status for job in submission.trainings} == {
            TrainingStatus.trained,
            TrainingStatus.failed,
            TrainingStatus.cancelled,
        }
        shown = submissions.detail(session, submission).training  # why it failed
        assert (shown.seed, shown.seeds, shown.failure) == (1, 3, "train_crashed")
        third_job = session.get(TrainingJob, third.training_id)
        assert third_job.status == TrainingStatus.cancelled
        assert submission.runs[0].status == RunStatus.cancelled
    with db.session() as session:  # seed 2's worker learns on its next heartbeat
        assert not training.heartbeat(session, settings.service, third, "w1", 1.0, "")
    with db.session() as session:  # the cancelled run's episode tasks do nothing
        episode = plan.episodes[0]
        assert claim_episode(session, settings, plan, episode) is None


def test_a_seeds_evaluation_lost_on_our_side_waits_while_the_others_go_on(db, settings):
    set_seeds(db, settings, 2)
    sid = offline(db)
    plans = [trained(db, settings, claim(db, settings, i)) for i in start(db, settings, sid)]
    with db.session() as session:  # seed 1's run loses an episode on our side
        run_id = plans[1].run_id
        first = plans[1].episodes[0]
        job = evaluation.claim_scenario(
            session,
            settings.service,
            settings.sandbox,
            run_id,
            first.scenario_id,
            "w1",
            first.index,
        )
    outcome = ScenarioOutcome(
        scenario_id=first.scenario_id,
        status=ScenarioStatus.evaluator_error,
        steps=0,
        agents=(),
        record_path=None,
        error="simulator died",
    )
    with db.session() as session:
        evaluation.record_scenario(session, job, "w1", outcome, "")
    rest = dataclasses.replace(plans[1], episodes=plans[1].episodes[1:])
    assert evaluate(db, settings, rest, fails=0) == RunStatus.failed
    with db.read_session() as session:
        submission = session.get(Submission, sid)
        assert submission.status == SubmissionStatus.running  # not failed: not the team's
        assert submission.status_reason.startswith(
            "seed 1 (of 2): evaluation failed on our side (1 scenario(s)), not the submission's"
        )
        assert submission.runs[0].status == RunStatus.queued  # seed 0's goes on
    assert evaluate(db, settings, plans[0], fails=0) == RunStatus.scored
    assert status_of(db, sid) == SubmissionStatus.running  # seed 1 still to come
    queue = TaskQueue(settings)
    try:
        said = admin.requeue(db, settings, queue, sid)
    finally:
        queue.close()
    assert said == "seed(s) 1 lost on our side: evaluated again"
    with db.read_session() as session:
        submission = session.get(Submission, sid)
        again = submission.runs[-1]
        assert (again.training.seed, again.status, again.attempt) == (1, RunStatus.queued, 3)
        plan = dataclasses.replace(plans[1], run_id=again.id)
    assert evaluate(db, settings, plan, fails=0) == RunStatus.scored
    assert status_of(db, sid) == SubmissionStatus.scored
    with db.read_session() as session:
        score = session.scalar(select(SeedSetScore))
        assert [s["run_id"] for s in score.per_seed] == [plans[0].run_id, plan.run_id]


def test_seeds_evaluated_on_different_suites_are_not_scored_together(db, settings):
    set_seeds(db, settings, 2)
    sid = offline(db)
    plans = [trained(db, settings, claim(db, settings, i)) for i in start(db, settings, sid)]
    assert evaluate(db, settings, plans[0], fails=0) == RunStatus.scored
    with db.session() as session:  # as if the phase's suite changed before seed 1's run
        session.get(EvaluationRun, plans[1].run_id).manifest_sha256 = "another suite"
    assert evaluate(db, settings, plans[1], fails=0) == RunStatus.scored
    with db.read_session() as session:
        submission = session.get(Submission, sid)
        assert submission.status == SubmissionStatus.failed
        assert submission.failed_on_our_side  # not the team's: it costs no try
        assert "different suites" in submission.status_reason
        assert session.scalar(select(SeedSetScore)) is None


def test_rerun_retrain_and_requeue_act_on_the_whole_set(db, settings):
    set_seeds(db, settings, 2)
    sid = offline(db)
    for training_id in start(db, settings, sid):
        evaluate(db, settings, trained(db, settings, claim(db, settings, training_id)), fails=0)
    assert status_of(db, sid) == SubmissionStatus.scored
    queue = TaskQueue(settings)
    try:
        assert admin.rerun(db, settings, queue, sid) == 3  # runs 3 and 4, one per seed
        with db.read_session() as session:
            runs = session.get(Submission, sid).runs
            active = [r.training.seed for r in runs if r.status == RunStatus.queued]
            assert active == [0, 1]
        with db.session() as session:
            for run in session.get(Submission, sid).runs:
                if run.status == RunStatus.queued:
                    evaluation.cancel_run(session, run)
        assert admin.retrain(db, settings.service, queue, sid) == 3  # jobs 3 and 4: seed set 2
        with db.read_session() as session:
            jobs = session.get(Submission, sid).trainings
            assert [(j.seed_set, j.seed, j.status) for j in jobs] == [
                (1, 0, "trained"),
                (1, 1, "trained"),
                (2, 0, "queued"),
                (2, 1, "queued"),
            ]
        assert admin.requeue(db, settings, queue, sid) == "2 trainings re-sent"
    finally:
        queue.close()
    assert status_of(db, sid) == SubmissionStatus.scored  # the first set's score stands


def test_a_phase_trains_1_to_16_seeds(db, settings):
    for wrong in (0, 17):
        with pytest.raises(InvalidInput, match="training seeds"):
            set_seeds(db, settings, wrong)
    with db.read_session() as session:
        assert session.scalar(select(Phase).where(Phase.name == "final")).training_seeds == 1


def test_the_cli_sets_the_training_seeds(db, arena):
    assert "train 4 times (seeds 0 to 3)" in arena(
        "phases", "set", "final", "--training-seeds", "4"
    )
    assert "seeds" in arena("phases", "list")
    assert "1 to 16" in arena("phases", "set", "final", "--training-seeds", "17", ok=False)
    with db.read_session() as session:
        assert session.scalar(select(Phase).where(Phase.name == "final")).training_seeds == 4


def test_each_seeds_model_is_downloaded_by_its_seed(db, settings, client):
    set_seeds(db, settings, 2)
    sid = offline(db)
    ids = start(db, settings, sid)
    for training_id in ids:
        trained(db, settings, claim(db, settings, training_id))
    with pytest.raises(InvalidInput, match="2 seeds: choose one with --seed"):
        admin.trained_model(db, sid)
    models = [admin.trained_model(db, sid, seed) for seed in (0, 1)]
    assert [m.key for m in models] == [f"training/{i}/model.tar.gz" for i in ids]
    assert [m.seed for m in models] == [0, 1]
    # The organisers' REST route asks for the seed the same way.
    url = f"/api/v1/admin/submissions/{sid}/model"
    assert client.get(url, headers=bearer(ADMIN_TOKEN)).status_code == 422
    assert client.get(url, params={"seed": 5}, headers=bearer(ADMIN_TOKEN)).status_code == 404


def test_an_infrastructure_failure_on_one_seed_retries_that_seed_alone(db, settings, arena):
    """Seed 1 lost on our side (its retries used up, or its workers kept dying): the submission
    does not fail and the other seeds go on; requeue trains seed 1 again in the same set, and the
    submission is scored over all three."""
    set_seeds(db, settings, 3)
    sid = offline(db)
    ids = start(db, settings, sid)
    first, second, third = (claim(db, settings, i) for i in ids)
    plan0 = trained(db, settings, first)
    with db.session() as session:
        assert training.record_failed(
            session, second, "w1", failure="worker_lost", error="3 workers died", ours=True
        )
    with db.read_session() as session:
        submission = session.get(Submission, sid)
        assert submission.status == SubmissionStatus.running  # not failed
        assert not submission.failed_on_our_side
        assert submission.status_reason.startswith("seed 1 (of 3): training failed on our side")
        assert [r.status for r in submission.runs] == [RunStatus.queued]  # seed 0's goes on
        assert session.get(TrainingJob, third.training_id).status == TrainingStatus.training
    with db.session() as session:  # seed 2's worker keeps its claim
        assert training.heartbeat(session, settings.service, third, "w1", 1.0, "")
    assert evaluate(db, settings, plan0, fails=0) == RunStatus.scored
    assert evaluate(db, settings, trained(db, settings, third), fails=0) == RunStatus.scored
    assert status_of(db, sid) == SubmissionStatus.running  # seed 1 is still to come
    status = arena("status")  # the organisers are told what waits for them
    assert "training seeds waiting" in status
    assert f"{sid}\t1\ttraining" in status.splitlines()
    said = arena("submissions", "requeue", str(sid))
    assert said.strip() == "training re-sent; seed(s) 1 lost on our side: trained again"
    assert "training seeds waiting" not in arena("status")
    with db.read_session() as session:
        jobs = session.get(Submission, sid).trainings
        assert [(j.seed_set, j.seed, j.status) for j in jobs] == [
            (1, 0, "trained"),
            (1, 1, "failed"),  # kept: what happened to it
            (1, 2, "trained"),
            (1, 1, "queued"),
        ]
        assert session.get(Submission, sid).status_reason == ""
        again = jobs[-1].id
    assert evaluate(db, settings, trained(db, settings, claim(db, settings, again)), fails=0) == (
        RunStatus.scored
    )
    assert status_of(db, sid) == SubmissionStatus.scored
    with db.read_session() as session:
        score = session.scalar(select(SeedSetScore))
        assert [(s["seed"], s["training_id"]) for s in score.per_seed] == [
            (0, ids[0]),
            (1, again),
            (2, ids[2]),
        ]


def test_one_seed_of_one_lost_on_our_side_fails_uncharged(db, settings):
    """A set of one seed has nothing to go on with: an organiser retrains it."""
    sid = offline(db)
    (only,) = (claim(db, settings, i) for i in start(db, settings, sid))
    with db.session() as session:
        training.record_failed(
            session, only, "w1", failure="SandboxUnavailable", error="no bwrap", ours=True
        )
    with db.read_session() as session:
        submission = session.get(Submission, sid)
        assert submission.status == SubmissionStatus.failed
        assert submission.failed_on_our_side
        assert submission.status_reason == "SandboxUnavailable: no bwrap"


def test_failure_counts_and_the_manifest_cover_every_seed(db, settings, client):
    set_seeds(db, settings, 2)
    team_id, token = make_team(db, "api")
    sid = queued_submission(db, team_id, track=Track.offline)
    ids = start(db, settings, sid)
    for training_id, fails in zip(ids, (1, 2), strict=True):
        evaluate(db, settings, trained(db, settings, claim(db, settings, training_id)), fails)
    shown = client.get(f"/api/v1/submissions/{sid}", headers=bearer(token)).json()

    def collisions(counts: dict) -> int:
        return sum(reasons.get("collision", 0) for reasons in counts.values())

    assert collisions(shown["failure_reasons"]) == 3  # summed over the seeds
    per_seed = shown["seed_failure_reasons"]
    assert [(s["seed"], collisions(s["failure_reasons"])) for s in per_seed] == [(0, 1), (1, 2)]
    manifest = shown["manifest"]
    assert manifest["model"] is None
    assert manifest["seed_models"] == [
        {"seed": seed, "model": f"{training_id:064x}"} for seed, training_id in enumerate(ids)
    ]
    download = client.get(f"/api/v1/submissions/{sid}/download", headers=bearer(token))
    with zipfile.ZipFile(io.BytesIO(download.content)) as archive:
        stored = json.loads(archive.read("submission.json"))
    assert stored["seed_failure_reasons"] == per_seed
    assert stored["manifest"]["seed_models"] == manifest["seed_models"]


def seed_set(db, settings, team: str, fails: tuple[int, ...]) -> int:
    """An offline submission trained with len(fails) seeds, seed k failing fails[k] scenarios."""
    set_seeds(db, settings, len(fails))
    sid = offline(db, team)
    for training_id, failing in zip(start(db, settings, sid), fails, strict=True):
        evaluate(db, settings, trained(db, settings, claim(db, settings, training_id)), failing)
    assert status_of(db, sid) == SubmissionStatus.scored
    return sid


def test_compare_sets_seed_set_scores_side_by_side_and_each_seed(db, settings, arena, client):
    a = seed_set(db, settings, "alpha", (1, 2))
    b = seed_set(db, settings, "beta", (0, 0))
    with db.read_session() as session:
        means = {s.submission_id: s.completion for s in session.scalars(select(SeedSetScore)).all()}
    output = arena("compare", str(a), str(b))
    assert f"A: submission {a} of alpha (final, 2 training seeds" in output
    rows = {line.split("\t")[0]: line.split("\t")[1:] for line in output.splitlines()}
    assert rows["completion"][:2] == [f"{means[a]:.4f}", f"{means[b]:.4f}"]  # the sets' means
    assert rows["training seeds"] == ["2", "2"]
    # A set's interval resamples seeds and scenarios: labelled, lest it be read as one run's.
    assert all(
        c.endswith("] over 2 seeds x scenarios") for c in rows["completion 95% interval"][:2]
    )
    assert rows["seeds' completion"][1] == "0.0000 to 0.0000 (std 0.0000)"
    assert "per seed (seed k of A beside seed k of B)" in output
    assert "3 episode(s) ended differently" in output  # seed 0: one, seed 1: two
    document = json.loads(arena("compare", str(a), str(b), "--json"))
    seeds = document["seeds"]
    assert (seeds["a"]["count"], seeds["b"]["completion_max"]) == (2, 0.0)
    assert [(p["seed_a"], p["seed_b"], len(p["differing_outcomes"])) for p in seeds["pairs"]] == [
        (0, 0, 1),
        (1, 1, 2),
    ]
    assert {o["b"] for p in seeds["pairs"] for o in p["differing_outcomes"]} == {"reached_goal"}
    # The organisers' REST route answers the same document.
    compared = client.get(
        "/api/v1/admin/compare", params={"a": a, "b": b}, headers=bearer(ADMIN_TOKEN)
    )
    assert compared.status_code == 200, compared.text
    assert compared.json() == document
    # A submission of one run beside a seed set: its run beside each seed.
    single = seed_set(db, settings, "gamma", (1,))
    document = json.loads(arena("compare", str(single), str(a), "--json"))
    assert document["seeds"]["a"] is None
    assert [(p["seed_a"], p["seed_b"]) for p in document["seeds"]["pairs"]] == [
        (None, 0),
        (None, 1),
    ]
    assert [len(p["differing_outcomes"]) for p in document["seeds"]["pairs"]] == [0, 1]
    assert "its run" in arena("compare", str(single), str(a))


def test_while_a_new_seed_set_is_under_way_the_standing_score_is_compared_and_counted(
    db, settings, client
):
    """Scored with one seed, retrained with two (seed 0 scored, seed 1 to come): the score that
    stands is still the first run's, and compare, the failure counts and the manifest are its."""
    team_id, token = make_team(db, "alpha")
    sid = queued_submission(db, team_id, track=Track.offline)
    (first,) = start(db, settings, sid)
    evaluate(db, settings, trained(db, settings, claim(db, settings, first)), fails=1)
    set_seeds(db, settings, 2)
    queue = TaskQueue(settings)
    try:
        admin.retrain(db, settings.service, queue, sid)
    finally:
        queue.close()
    with db.read_session() as session:
        jobs = seed_sets.latest_set(session.get(Submission, sid))
        new_ids = [job.id for job in jobs]
    evaluate(db, settings, trained(db, settings, claim(db, settings, new_ids[0])), fails=2)
    side = admin.comparison_side(db, sid)
    assert side.seeds == () and side.label.endswith("attempt 1, m)")
    shown = client.get(f"/api/v1/submissions/{sid}", headers=bearer(token)).json()
    assert shown["seeds"] is None and shown["seed_failure_reasons"] == []
    assert sum(r.get("collision", 0) for r in shown["failure_reasons"].values()) == 1
    assert shown["manifest"]["model"] == f"{first:064x}"
