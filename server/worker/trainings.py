"""The training job kind: an offline (Track 2) submission's ``train.py`` run in the sandbox, its
output packed into the artifact store, then the evaluation of that output sent
(:mod:`server.services.training` holds its transitions)."""

from __future__ import annotations

import contextlib
import shutil
from dataclasses import dataclass
from pathlib import Path

from sqlalchemy.orm import Session

from arena.config import ServiceSettings, Settings
from arena.errors import DatasetError
from evaluator.runner import new_run_key
from evaluator.training import MODEL_ARCHIVE, TrainingResult, TrainingStopped, pack_model, train
from evaluator.training.metrics import METRICS_FILE
from server.core.queue import TaskQueue
from server.jobs.heartbeat import beat_interval_s
from server.jobs.kind import Lease
from server.services import training
from server.services.training import TrainingClaim
from server.services.training_curves import CurvePublisher
from server.worker import checkpoints, local


@dataclass(frozen=True)
class OurFailure:
    """A training that ended without a model through no fault of the team (not charged)."""

    failure: str
    error: str


class Trainings:
    name = "training"
    max_claims = 3

    def claim(
        self, session: Session, settings: Settings, worker: str, *, training_id: int
    ) -> TrainingClaim | None:
        return training.claim_training(session, settings.service, training_id, worker)

    def renew(
        self,
        session: Session,
        service: ServiceSettings,
        claim: TrainingClaim,
        worker: str,
        *,
        elapsed_s: float | None = None,
        log_tail: str | None = None,
    ) -> bool:
        return training.heartbeat(session, service, claim, worker, elapsed_s, log_tail)

    def release(self, session: Session, claim: TrainingClaim, worker: str) -> bool:
        return training.release(session, claim, worker)

    def send_again(self, queue: TaskQueue, claim: TrainingClaim) -> None:
        queue.train(claim.training_id)

    def run(
        self, claim: TrainingClaim, lease: Lease, settings: Settings
    ) -> TrainingResult | OurFailure | None:
        """Run the submission's train.py; its progress is shown with each renewal of the lease,
        and a lost claim or a stopping worker ends it (None)."""
        if settings.training.train_dataset_dir is None:
            return OurFailure(
                "no_dataset", "the service has no training dataset (ARENA_TRAIN_DATASET_DIR)"
            )
        output = _output(claim)
        shutil.rmtree(output.parent, ignore_errors=True)  # an earlier claim's leftovers here
        saved = checkpoints.ClaimCheckpoints(
            local.store(),
            settings.training,
            claim.training_id,
            claim.claim_number,
            output,
            staging=output.parent,
        )
        resume_from = saved.latest()
        curves = CurvePublisher(local.store(), claim.training_id, output)

        def progress(elapsed_s: float, log: str) -> bool:
            alive = lease.report(elapsed_s=elapsed_s, log_tail=local.tail(log))
            if alive:  # only the live claim saves; the heartbeat thread renews meanwhile
                saved.save_if_due()
                curves.publish()  # shown while it trains
            return alive

        try:
            return train(
                local.prepared(claim.upload_key),
                settings.training.train_dataset_dir,
                output,
                training=settings.training,
                config=settings.sandbox,
                data_dir=settings.storage.resolved_data_dir,
                kind=local.sandbox_kind(),
                labels={
                    "arena.training": f"t{claim.training_id}c{claim.claim_number}-{new_run_key()}"
                },
                on_progress=progress,
                progress_every_s=beat_interval_s(settings.service.lease_seconds),
                resume_from=resume_from,
                seed=claim.seed,
            )
        except TrainingStopped:
            with local.database().session() as session:
                over = training.ended(session, claim.training_id)
            if over:  # cancelled (e.g. another seed failed): nothing will resume from them
                checkpoints.discard(local.store(), claim.training_id, claim.claim_number)
            return None
        except DatasetError as exc:
            return OurFailure("no_dataset", str(exc))

    def ours(self, claim: TrainingClaim, reason: str, error: str) -> OurFailure:
        return OurFailure(reason, error)

    def finish(
        self,
        claim: TrainingClaim,
        worker: str,
        result: TrainingResult | OurFailure,
        settings: Settings,
    ) -> None:
        """Store the trained output and send its evaluation, or record the failure. Either way
        the training is over: its checkpoints go."""
        checkpoints.discard(local.store(), claim.training_id, claim.claim_number)
        if isinstance(result, OurFailure):
            with local.database().session() as session:
                training.record_failed(
                    session, claim, worker, failure=result.failure, error=result.error, ours=True
                )
            return
        tail = local.tail(result.log)
        output = _output(claim)
        CurvePublisher(local.store(), claim.training_id, output).publish()  # the last points
        # Not part of the model: a curve's timing must not make two seeds' models differ.
        with contextlib.suppress(OSError):  # missing, or a folder of that name (left in)
            (output / METRICS_FILE).unlink()
        if not result.ok:
            shutil.rmtree(_output(claim).parent, ignore_errors=True)
            with local.database().session() as session:
                training.record_failed(
                    session,
                    claim,
                    worker,
                    failure=str(result.failure),
                    error=result.detail,
                    elapsed_s=result.elapsed_s,
                    log_tail=tail,
                )
            return
        key, sha256, size = _store_model(claim)
        with local.database().session() as session:
            plan = training.record_trained(
                session,
                settings,
                claim,
                worker,
                elapsed_s=result.elapsed_s,
                log_tail=tail,
                model_key=key,
                model_sha256=sha256,
                model_size=size,
            )
        if plan is not None:
            local.queue().send(plan)

    def reap(self, service: ServiceSettings, queue: TaskQueue, *, queue_empty: bool) -> int:
        with local.database().session() as session:
            resend = training.reap(session, service, queue_empty=queue_empty)
        for training_id in resend:
            queue.train(training_id)
        return len(resend)


def _output(claim: TrainingClaim) -> Path:
    return local.scratch() / "training" / str(claim.training_id) / f"claim-{claim.claim_number}"


def _store_model(claim: TrainingClaim) -> tuple[str, str, int]:
    """Pack the trained output into the artifact store: (key, sha256, size [bytes])."""
    output = _output(claim)
    archive = output.parent / MODEL_ARCHIVE
    sha256 = pack_model(output, archive)
    size = archive.stat().st_size
    key = f"training/{claim.training_id}/claim-{claim.claim_number}/{MODEL_ARCHIVE}"
    local.store().put(key, archive)
    shutil.rmtree(output.parent, ignore_errors=True)
    return key, sha256, size


TRAININGS = Trainings()
