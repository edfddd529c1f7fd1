"""Training curves of Track 2 submissions (:mod:`evaluator.training.metrics`): published by the
worker into the artifact store while ``train.py`` runs, drawn for whoever may see them: its team
in a phase whose results it sees in full, the organisers always."""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

from sqlalchemy.orm import Session

from evaluator.training.metrics import Curve, read_curves
from server.charts import curves_chart
from server.core.artifacts import ArtifactStore, MissingArtifact
from server.models import Submission
from server.services import phases
from server.services.errors import Forbidden, NotFound
from server.services.seed_sets import latest_set
from server.status import ACTIVE_TRAINING


def curves_key(training_id: int) -> str:
    return f"training/{training_id}/curves.json"


class CurvePublisher:
    """Publishes one training's curves from its output folder, only when they changed."""

    def __init__(self, store: ArtifactStore, training_id: int, output: Path) -> None:
        self.store, self.training_id, self.output = store, training_id, output
        self._published: list[Curve] | None = None

    def publish(self) -> None:
        curves = read_curves(self.output)
        if curves == self._published or (not curves and self._published is None):
            return
        with tempfile.TemporaryDirectory() as folder:
            path = Path(folder) / "curves.json"
            path.write_text(json.dumps([curve.to_json() for curve in curves]))
            self.store.put(curves_key(self.training_id), path)
        self._published = curves


def load_curves(store: ArtifactStore, training_id: int) -> list[Curve]:
    try:
        data = json.loads(store.read(curves_key(training_id)))
    except MissingArtifact:
        return []
    return [Curve.from_json(curve) for curve in data]


def training_svg(
    session: Session, store: ArtifactStore, submission: Submission, *, organiser: bool = False
) -> str:
    """The curves each seed's ``train.py`` logged in the submission's latest trainings, as SVG.
    Its team sees them where it sees everything of the phase; organisers always."""
    if not organiser and not phases.team_sees_everything(
        phases.get_phase(session, submission.phase)
    ):
        raise Forbidden(
            f"in the {submission.phase!r} phase training curves go to the organisers only; "
            "train locally (`arena train`) or in the validation phase to see them"
        )
    jobs = latest_set(submission)
    if not jobs:
        raise NotFound(f"submission {submission.id} has no training")
    return curves_chart(
        {job.seed: load_curves(store, job.id) for job in jobs},
        live=any(job.status in ACTIVE_TRAINING for job in jobs),
    )
