"""The episode job kind: one episode of one scenario of an evaluation run, simulated with the
submission's agent in the sandbox (:mod:`server.services.evaluation` holds its transitions)."""

from __future__ import annotations

import dataclasses
import logging
from functools import partial
from pathlib import Path

from celery.utils.log import current_process_index
from sqlalchemy.orm import Session

from arena.config import ServiceSettings, Settings
from evaluator import sandbox
from evaluator.runner import new_run_key, sandbox_labels
from evaluator.runner import run_scenario as run_episode
from evaluator.runner.scenario import ScenarioOutcome
from evaluator.sandbox.placement import claimed_cpus
from server.core.queue import TaskQueue
from server.jobs.kind import Lease
from server.services import evaluation
from server.services.evaluation import ScenarioJob
from server.worker import local

log = logging.getLogger(__name__)


class Episodes:
    name = "episode"
    # Claims of one episode (a worker dying mid-episode releases its claim) before giving up.
    max_claims = 3

    def claim(
        self,
        session: Session,
        settings: Settings,
        worker: str,
        *,
        run_id: int,
        scenario_id: str,
        episode: int = 0,
    ) -> ScenarioJob | None:
        return evaluation.claim_scenario(
            session, settings.service, settings.sandbox, run_id, scenario_id, worker, episode
        )

    def renew(
        self,
        session: Session,
        service: ServiceSettings,
        claim: ScenarioJob,
        worker: str,
        **_: object,
    ) -> bool:
        return evaluation.heartbeat(session, service, claim, worker)

    def release(self, session: Session, claim: ScenarioJob, worker: str) -> bool:
        return evaluation.release_claim(session, claim, worker)

    def send_again(self, queue: TaskQueue, claim: ScenarioJob) -> None:
        queue.run_scenario(claim.run_id, claim.key)

    def run(self, claim: ScenarioJob, lease: Lease, settings: Settings) -> ScenarioOutcome:
        # Which worker ran what (claim > 1: an earlier claim's worker died or handed it back).
        log.info(
            "run %s: episode %d of %s claimed (claim %d)",
            claim.run_id,
            claim.episode,
            claim.scenario_id,
            claim.claim_number,
        )
        # Per run, claim and a random part: two submissions of the same zip (or two claims of one
        # episode) never share sandbox labels, and nothing in it names the scenario.
        run_key = f"r{claim.run_id}a{claim.claim_number}-{new_run_key()}"
        # A lost claim kills every sandbox of the episode (all its attempts carry these labels):
        # the runner then returns, and its result is refused by the fence.
        lease.stop_with(partial(sandbox.cleanup, settings.sandbox, sandbox_labels(run_key)))
        # This worker's own scratch folder, one per claim: an episode whose claim was superseded
        # never touches the live one's files.
        records = local.scratch() / "records" / str(claim.run_id) / f"claim-{claim.claim_number}"
        submission = local.prepared(claim.upload_key)
        if claim.model_key is not None:
            submission = dataclasses.replace(submission, model_dir=local.model(claim.model_key))
        # Each pool process is a job: its simulator and agent share a CPU no other job holds.
        job = current_process_index(base=0) or 0
        with claimed_cpus(job, settings.sandbox) as cpus:
            return run_episode(
                submission,
                Path(claim.scenario_dir),
                records,
                config=settings.sandbox,
                data_dir=settings.storage.resolved_data_dir,
                sandbox=local.sandbox_kind(),
                run_key=run_key,
                episode=claim.episode,
                limits=claim.limits,
                cpus=cpus,
            )

    def ours(self, claim: ScenarioJob, reason: str, error: str) -> ScenarioOutcome:
        return ScenarioOutcome.ours(
            claim.scenario_id,
            f"{reason}: {error} (claim {claim.claim_number})",
            attempts=claim.claim_number,
            episode=claim.episode,
        )

    def finish(
        self, claim: ScenarioJob, worker: str, result: ScenarioOutcome, settings: Settings
    ) -> None:
        """Store the episode; the one that finished the run's last episode sends its scoring."""
        record_key = _store_record(claim, result)
        log_tail = team_log_tail(claim, result)
        with local.database().session() as session:
            last = evaluation.record_scenario(session, claim, worker, result, log_tail, record_key)
        if last:
            local.queue().aggregate(claim.run_id)

    def reap(self, service: ServiceSettings, queue: TaskQueue, *, queue_empty: bool) -> int:
        """Lost episodes, runs whose tasks were all lost, and queued submissions whose first
        task never started (see :func:`server.services.evaluation.reap`)."""
        with local.database().session() as session:
            reaped = evaluation.reap(session, service, queue_empty=queue_empty)
        for plan in reaped.plans:
            queue.send(plan)
        for submission_id in reaped.submission_ids:
            queue.evaluate(submission_id)
        return sum(len(plan.episodes) + plan.aggregate for plan in reaped.plans) + len(
            reaped.submission_ids
        )


def team_log_tail(claim: ScenarioJob, outcome: ScenarioOutcome) -> str:
    """The tail of the episode's log the team may see: storable, without the scenario's id."""
    return local.tail(outcome.log.replace(claim.scenario_id, "<scenario>"))


def _store_record(claim: ScenarioJob, outcome: ScenarioOutcome) -> str | None:
    """Put the episode record in the artifact store, where any worker can score it."""
    if outcome.record_path is None:
        return None
    key = f"runs/{claim.run_id}/claim-{claim.claim_number}/{claim.key.name}.npz"
    local.store().put(key, outcome.record_path)
    outcome.record_path.unlink(missing_ok=True)
    return key


EPISODES = Episodes()
