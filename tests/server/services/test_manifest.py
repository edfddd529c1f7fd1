"""The reproducibility manifest through the service: written with the score from what the
episodes ran with, shown to the team without hidden scenario ids or seeds (REST, download)."""

from __future__ import annotations

import io
import json
import zipfile

from sqlalchemy import select

from arena.outcome import AgentOutcome, ScenarioStatus
from evaluator.provenance import Environment, Manifest
from evaluator.runner import ScenarioOutcome
from server.models import Score
from server.services import evaluation
from tests.server.builders import bearer, make_team, queued_submission, scenario_ids
from tests.server.worker.test_evaluation_flow import agent, aggregate, claim, job_of, start

HERE = Environment(
    arena="0.1.0",
    python="3.11.7",
    numpy="2.4.6",
    sumo="1.28.0",
    sandbox="docker",
    agent_image="sha256:" + "a" * 64,
)


def run_with_pins(db, settings, submission_id, environments=(HERE,)):
    """Every episode reported as a worker does, with its seed and environment."""
    plan = start(db, settings, submission_id)
    for k, sid in enumerate(scenario_ids(plan)):
        claim(db, settings, plan.run_id, sid)
        job, worker = job_of(db, plan.run_id, sid)
        outcome = ScenarioOutcome(
            scenario_id=sid,
            status=ScenarioStatus.done,
            steps=0,
            agents=(AgentOutcome(**agent(True)),),
            record_path=None,
            seed=1000 + k,
            environment=environments[k % len(environments)],
        )
        with db.session() as session:
            evaluation.record_scenario(session, job, worker, outcome, "", record_key=None)
    aggregate(db, plan.run_id)


def test_a_score_carries_its_manifest_and_the_team_sees_it_without_hidden_ids(client, db, settings):
    team, token = make_team(db, "alpha")
    sid = queued_submission(db, team)
    run_with_pins(db, settings, sid)
    with db.read_session() as session:
        manifest = Manifest.model_validate(session.scalar(select(Score)).manifest)
    hidden_ids = sorted(manifest.scenarios)
    assert [pin.seeds for pin in manifest.scenarios.values()] == [(1000,), (1001,), (1002,)]
    assert manifest.environments == (HERE,)
    assert manifest.profile == "driving-smarts-2022" and manifest.model is None

    shown = client.get(f"/api/v1/submissions/{sid}", headers=bearer(token)).json()["manifest"]
    assert shown["submission"] == manifest.submission
    assert shown["suite_hash"] == manifest.suite_hash
    assert shown["scenario_hashes"] == sorted(p.hash for p in manifest.scenarios.values())
    assert shown["environments"] == [HERE.model_dump()]
    assert len(shown["seeds_sha256"]) == 64
    text = json.dumps(shown)
    assert not any(hidden in text for hidden in hidden_ids) and "1001" not in text

    download = client.get(f"/api/v1/submissions/{sid}/download", headers=bearer(token))
    with zipfile.ZipFile(io.BytesIO(download.content)) as archive:
        assert json.loads(archive.read("submission.json"))["manifest"] == shown


def test_episodes_run_under_two_environments_are_both_named(client, db, settings):
    team, token = make_team(db, "alpha")
    sid = queued_submission(db, team)
    other = HERE.model_copy(update={"sumo": "1.27.0"})
    run_with_pins(db, settings, sid, environments=(HERE, other))
    shown = client.get(f"/api/v1/submissions/{sid}", headers=bearer(token)).json()["manifest"]
    assert [env["sumo"] for env in shown["environments"]] == ["1.28.0", "1.27.0"]
