"""The validation job kind: an uploaded zip checked, extracted and compiled, and its requirements
unpacked, in the sandbox (:mod:`evaluator.validation`); the submission then queued for evaluation
or rejected naming the rule it broke (:mod:`server.services.validation` holds its transitions).
Its scratch folder is removed when it ends, whatever the verdict."""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from pathlib import Path

from sqlalchemy.orm import Session

from arena.config import (
    IntakeSettings,
    SandboxKind,
    SandboxSettings,
    ServiceSettings,
    Settings,
    get_settings,
)
from arena.errors import IntakeError
from evaluator import sandbox
from evaluator.runner import new_run_key
from evaluator.validation import validate
from server.core.artifacts import ArtifactStore
from server.core.db import Database
from server.core.queue import TaskQueue
from server.jobs.kind import Lease
from server.models import Submission
from server.services import validation
from server.services.validation import ValidationClaim
from server.worker import local
from submissions.intake import PreparedSubmission
from submissions.intake.archive import remove_tree
from submissions.intake.contents import REQUIREMENTS
from submissions.intake.dependencies import collect_garbage, exclusive_bytes


@dataclass(frozen=True)
class Verdict:
    prepared: PreparedSubmission | None  # None: rejected
    reason: str = ""  # the rule broken, as the team reads it
    ours: bool = False  # failed on our side (not charged)


class Validations:
    name = "validation"
    max_claims = 3

    def claim(
        self, session: Session, settings: Settings, worker: str, *, submission_id: int
    ) -> ValidationClaim | None:
        # The task is a token: the fairest waiting validation is taken, whichever it names.
        del submission_id
        return validation.claim(session, settings.service, settings.intake, worker)

    def renew(
        self,
        session: Session,
        service: ServiceSettings,
        claim: ValidationClaim,
        worker: str,
        **_: object,
    ) -> bool | str:
        return validation.renew(session, service, claim, worker)

    def release(self, session: Session, claim: ValidationClaim, worker: str) -> bool:
        return validation.release(session, claim, worker)

    def send_again(self, queue: TaskQueue, claim: ValidationClaim) -> None:
        queue.validate(claim.submission_id)

    def run(self, claim: ValidationClaim, lease: Lease, settings: Settings) -> Verdict | None:
        if claim.time_budget_s <= 0:
            return Verdict(None, _budget_spent(settings.intake))
        # A random part, as an episode's and a training's labels have: a validation handed back
        # gets its claim number again (validation.release), and the stopping worker's hook of
        # the earlier claim (server/jobs/heartbeat.py) must not kill the next claim's sandbox.
        run_key = new_run_key()
        labels = {"arena.validation": f"s{claim.submission_id}c{claim.claim_number}-{run_key}"}
        lease.stop_with(partial(sandbox.cleanup, settings.sandbox, labels))
        try:
            verdict = judge(
                claim,
                local.store(),
                local.sandbox_kind(),
                labels,
                local.scratch(),
                # At most what is left of the team's validation time today.
                intake=settings.intake.model_copy(update={"intake_timeout_s": claim.time_budget_s}),
                config=settings.sandbox,
                data_dir=settings.storage.resolved_data_dir,
            )
        except Exception:
            if lease.stopped:  # killed on purpose (handed back, or the claim lost)
                return None
            raise
        if verdict.prepared is not None and verdict.prepared.deps_key is not None:
            over = team_share_exceeded(
                local.database(),
                settings.intake,
                settings.storage.resolved_data_dir,
                claim.submission_id,
                verdict.prepared.deps_key,
            )
            verdict = verdict if over is None else Verdict(None, over)
        return None if lease.stopped else verdict

    def ours(self, claim: ValidationClaim, reason: str, error: str) -> Verdict:
        return Verdict(None, f"validation failed on our side ({reason}): {error}", ours=True)

    def finish(
        self, claim: ValidationClaim, worker: str, result: Verdict, settings: Settings
    ) -> None:
        record(
            claim,
            worker,
            result,
            local.database(),
            local.store(),
            local.queue(),
            intake=settings.intake,
            data_dir=settings.storage.resolved_data_dir,
        )

    def reap(self, service: ServiceSettings, queue: TaskQueue, *, queue_empty: bool) -> int:
        with local.database().session() as session:
            resend = validation.reap(session, service, queue_empty=queue_empty)
        for submission_id in resend:
            queue.validate(submission_id)
        # The reaper is a task body: it reads the settings. Cancelled, disqualified and
        # rejected submissions' requirements are freed here whoever ended them.
        settings = get_settings()
        free_requirements(local.database(), settings.intake, settings.storage.resolved_data_dir)
        return len(resend)


def _budget_spent(intake: IntakeSettings) -> str:
    error = IntakeError(
        "<zip>",
        "validation-budget",
        f"your team's validations used its {intake.validation_budget_s:g} s of validation time "
        "today before this one could run: upload again after 00:00 UTC",
    )
    return str(error)


def judge(
    claim: ValidationClaim,
    store: ArtifactStore,
    kind: SandboxKind,
    labels: dict[str, str],
    scratch: Path,
    *,
    intake: IntakeSettings,
    config: SandboxSettings,
    data_dir: Path,
) -> Verdict:
    """The verdict on the claimed upload: its zip fetched into ``scratch`` and validated in the
    sandbox (``intake``, ``config``, ``data_dir``: as :func:`evaluator.validation.validate`
    takes them); the scratch folder is gone when this returns."""
    # A folder of this run's own, not of its claim number: a handed-back validation is claimed
    # again with the same number, and the earlier run's removal must not take the later's files.
    folder = scratch / "validation" / f"{claim.submission_id}-c{claim.claim_number}-{new_run_key()}"
    try:
        zip_path = store.fetch(claim.upload_key, folder / "upload.zip")
        return Verdict(
            validate(
                zip_path,
                folder / "prepared",
                intake,
                config,
                data_dir,
                kind=kind,
                labels=labels,
                needs_training=claim.needs_training,
            )
        )
    except IntakeError as exc:
        return Verdict(None, str(exc))
    finally:
        remove_tree(folder)


def record(
    claim: ValidationClaim,
    worker: str,
    result: Verdict,
    db: Database,
    store: ArtifactStore,
    queue: TaskQueue,
    *,
    intake: IntakeSettings,
    data_dir: Path,
) -> None:
    """Queue the submission's evaluation, or record the rejection (its zip and any requirement
    folder only it used, in ``data_dir``'s cache, are deleted)."""
    with db.session() as session:
        if result.prepared is not None:
            written = validation.record_valid(
                session,
                claim,
                worker,
                deps_key=result.prepared.deps_key,
                explanation=result.prepared.explanation,
            )
        else:
            written = validation.record_rejected(
                session, claim, worker, result.reason, ours=result.ours
            )
    if written and result.prepared is not None:
        queue.evaluate(claim.submission_id)
    elif written:
        store.delete_prefix(str(Path(claim.upload_key).parent))
    # Not written: the submission was cancelled meanwhile; its folder is freed now too.
    free_requirements(db, intake, data_dir)


def team_share_exceeded(
    db: Database, intake: IntakeSettings, data_dir: Path, submission_id: int, deps_key: str
) -> str | None:
    """Why the submission's requirements would take its team past its share of the wheel store
    (``max_team_deps_bytes``: the wheels no other team uses, unpacked), or None."""
    with db.read_session() as session:
        team_id = session.get(Submission, submission_id).team_id
        keys = validation.deps_by_team(session)
    keys.setdefault(team_id, set()).add(deps_key)
    charged = exclusive_bytes(data_dir, {str(team): held for team, held in keys.items()})
    used = charged[str(team_id)]
    if used <= intake.max_team_deps_bytes:
        return None
    cap = intake.max_team_deps_bytes / 1024**3
    return str(
        IntakeError(
            REQUIREMENTS,
            "team-deps-bytes",
            f"your team's own wheels (those no other team uses) would take {used / 1024**3:.1f} "
            f"GiB unpacked with this submission, over the team's {cap:g} GiB: cancel older "
            "submissions you no longer need, or build on an organiser stack",
        )
    )


def free_requirements(db: Database, intake: IntakeSettings, data_dir: Path) -> int:
    """Delete the requirement folders (and stored wheels) no submission that may still run
    uses; folders younger than a few validations may belong to one not yet recorded."""
    with db.read_session() as session:
        in_use = validation.deps_in_use(session)
        released = validation.deps_released(session) - in_use
    age = 4 * (intake.intake_timeout_s + intake.resolver_timeout_s)
    return collect_garbage(data_dir, in_use, min_age_s=age, released=released)


VALIDATIONS = Validations()
