"""A training's checkpoints in the artifact store: saved while ``train.py`` runs, handed to the
claim that takes the training over when its worker died or stopped (docs/dataset.md).

Every claim saves under a key of its own, so a claim presumed dead that still runs never
overwrites the live claim's snapshot; a claim's first save removes the earlier claims' ones. A
job therefore holds at most a few archives, each at most ``ARENA_TRAIN_CHECKPOINT_BYTES``, and
none once it ended (:func:`discard`). A failed save is logged and tried again at the next
interval: it never stops the training.
"""

from __future__ import annotations

import logging
from pathlib import Path

from sqlalchemy.exc import SQLAlchemyError

from arena.config import TrainingSettings
from evaluator.training.checkpoint import CheckpointWatch, SnapshotFailed
from server.core.artifacts import ArtifactStore, MissingArtifact

log = logging.getLogger(__name__)

STORE_ERRORS = (OSError, SQLAlchemyError)


def checkpoint_key(training_id: int, claim: int) -> str:
    return f"training/{training_id}/checkpoints/claim-{claim}.tar.gz"


class ClaimCheckpoints:
    """The checkpoints of one claim of a training job; ``output`` is its ARENA_MODEL_DIR and
    ``staging`` a folder of the worker's own for the archives."""

    def __init__(
        self,
        store: ArtifactStore,
        training: TrainingSettings,
        training_id: int,
        claim: int,
        output: Path,
        staging: Path,
    ) -> None:
        self.store = store
        self.training_id = training_id
        self.claim = claim
        self.staging = staging
        self.watch = CheckpointWatch(
            output,
            interval_s=training.train_checkpoint_interval_s,
            max_bytes=training.train_checkpoint_bytes,
            max_entries=training.train_output_files,
        )
        self._saved = False

    def latest(self) -> Path | None:
        """The last snapshot an earlier claim saved, fetched; None when there is none."""
        for claim in range(self.claim - 1, 0, -1):
            try:
                archive = self.store.fetch(
                    checkpoint_key(self.training_id, claim), self.staging / "resume.tar.gz"
                )
            except MissingArtifact:
                continue
            except STORE_ERRORS as error:
                log.warning("checkpoint of training %s unreadable: %s", self.training_id, error)
                return None
            log.warning("training %s resumes from claim %d's checkpoint", self.training_id, claim)
            return archive
        return None

    def save_if_due(self) -> None:
        if not self.watch.due():
            return
        archive = self.staging / "checkpoint.tar.gz"
        try:
            if not self.watch.snapshot(archive):
                return
            self.store.put(checkpoint_key(self.training_id, self.claim), archive)
        except SnapshotFailed as error:
            log.info("training %s: checkpoint not saved: %s", self.training_id, error)
            return
        except STORE_ERRORS as error:
            log.warning("training %s: checkpoint not stored: %s", self.training_id, error)
            return
        finally:
            archive.unlink(missing_ok=True)
        if not self._saved:
            self._saved = True
            for claim in range(1, self.claim):
                try:
                    self.store.delete_prefix(checkpoint_key(self.training_id, claim))
                except STORE_ERRORS as error:
                    log.warning("training %s: old checkpoint kept: %s", self.training_id, error)


def discard(store: ArtifactStore, training_id: int, claim: int) -> None:
    """Claim ``claim`` of the training ended it (trained or failed): its checkpoints and the
    earlier claims' are of no more use. A later claim's are kept: if this claim was superseded
    meanwhile, the live one still saves and resumes from its own."""
    try:
        for earlier in range(1, claim + 1):
            store.delete_prefix(checkpoint_key(training_id, earlier))
    except STORE_ERRORS as error:
        log.warning("checkpoints of training %s not removed: %s", training_id, error)
