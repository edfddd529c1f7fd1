"""Track 2 training curves: published by the worker from the metrics file while train.py runs,
drawn for the team in a phase it sees in full, for the organisers always."""

from __future__ import annotations

import xml.etree.ElementTree as ET

from evaluator.training.metrics import METRICS_FILE
from server.core.artifacts import artifact_store
from server.models import Submission, TrainingJob
from server.services.training_curves import CurvePublisher
from server.status import TrainingStatus
from server.tracks import Track
from tests.server.builders import bearer, make_team, queued_submission
from tests.server.conftest import ADMIN_TOKEN

SVG = "{http://www.w3.org/2000/svg}"


def training(db, team_id: int, phase: str, seeds: int = 2) -> tuple[int, list[int]]:
    """An offline submission whose ``seeds`` trainings run now."""
    sid = queued_submission(db, team_id, track=Track.offline, phase=phase)
    with db.session() as session:
        session.get(Submission, sid).status = "training"
        jobs = [
            TrainingJob(
                submission_id=sid, attempt=1 + seed, seed=seed, seeds=seeds,
                status=TrainingStatus.training, elapsed_s=30.0, log_tail="",
            )
            for seed in range(seeds)
        ]  # fmt: skip
        session.add_all(jobs)
        session.flush()
        return sid, [job.id for job in jobs]


def publish(settings, db, tmp_path, training_id: int, lines: str) -> CurvePublisher:
    output = tmp_path / f"output-{training_id}"
    output.mkdir(exist_ok=True)
    (output / METRICS_FILE).write_text(lines)
    publisher = CurvePublisher(artifact_store(settings.storage, db), training_id, output)
    publisher.publish()
    return publisher


def polylines(svg: str) -> list[ET.Element]:
    return [e for e in ET.fromstring(svg).iter(f"{SVG}polyline")]


def test_each_seeds_curves_are_drawn_live_for_the_team(client, db, settings, tmp_path):
    team, token = make_team(db, "alpha")
    sid, (seed0, seed1) = training(db, team, "validation")
    url = f"/api/v1/submissions/{sid}/training.svg"
    empty = client.get(url, headers=bearer(token))
    assert empty.status_code == 200 and "nothing logged yet" in empty.text
    live = publish(settings, db, tmp_path, seed0, "1,loss,0.9\n2,loss,0.5\n")
    publish(settings, db, tmp_path, seed1, "1,loss,0.8\n2,loss,0.7\n1,reward,3\n")
    response = client.get(url, headers=bearer(token))
    assert response.headers["content-type"].startswith("image/svg+xml")
    assert "training: updated as train.py writes" in response.text
    lines = polylines(response.text)
    # loss of both seeds, reward of seed 1: a panel per name, a line per seed.
    assert sorted(line.get("class") for line in lines) == [
        "curve seed-0", "curve seed-1", "curve seed-1"
    ]  # fmt: skip
    # The worker publishes again as train.py writes more.
    (live.output / METRICS_FILE).write_text("1,loss,0.9\n2,loss,0.5\n3,loss,0.25\n")
    live.publish()
    titles = [e.text for e in ET.fromstring(client.get(url, headers=bearer(token)).text).iter(
        f"{SVG}title")]  # fmt: skip
    assert "seed 0, loss: 0.25 at step 3" in titles


def test_a_hidden_phases_curves_go_to_the_organisers_only(client, db, settings, tmp_path):
    team, token = make_team(db, "alpha")
    sid, (seed0, _) = training(db, team, "final")
    publish(settings, db, tmp_path, seed0, "1,loss,0.9\n")
    refused = client.get(f"/api/v1/submissions/{sid}/training.svg", headers=bearer(token))
    assert refused.status_code == 403 and "organisers only" in refused.json()["detail"]
    organiser = client.get(
        f"/api/v1/admin/submissions/{sid}/training.svg", headers=bearer(ADMIN_TOKEN)
    )
    assert organiser.status_code == 200 and len(polylines(organiser.text)) == 1
