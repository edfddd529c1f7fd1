"""Evaluate one submission on a scenario set: ``arena evaluate``.

Up to ``jobs`` episodes run at once, each in its own simulator process with its own sandboxed
agent (the threads here only wait on those processes); the episodes of job i run, simulator and
agent, on that job's CPUs (``pin_jobs``, :mod:`evaluator.sandbox.placement`). A reactive
scenario runs ``episodes_per_scenario`` episodes, each with other traffic (:mod:`arena.episodes`).
``summary.json`` is rewritten as episodes start and finish (at most once per round of those that
finish and start together, and less often as it grows: :meth:`ResultsFolder.checkpoint`), so a
crash leaves a trace and a re-run with the same ``out_dir`` resumes where it stopped.
``agent_cpu.json`` keeps the CPU time the agent used: once it passes the evaluation's budget, no
more episodes start, a resumed run included (:mod:`evaluator.runner.cpu_budget`).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import shutil
import tempfile
import threading
import traceback
from collections.abc import Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ThreadPoolExecutor, wait
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from time import monotonic
from typing import Protocol

from arena.config import IntakeSettings, SandboxKind, SandboxSettings
from arena.cpu_limits import CpuLimits
from arena.episodes import Episode, episodes_of
from arena.errors import ArenaError, SandboxUnavailable
from arena.files import write_atomically
from arena.neutralise.storable import storable_text
from arena.outcome import ScenarioStatus
from arena.suite import Suite, load_suite
from evaluator.failures import FAIL_FAST_AFTER, never_started
from evaluator.provenance import EpisodeRun, Manifest, distinct, manifest_of
from evaluator.runner.cpu_budget import AGENT_CPU_FILE, CpuLedger
from evaluator.runner.results import (
    LOGS_DIR,
    RECORDS_DIR,
    ScoredEntry,
    done_entry,
    is_finished,
    outcome_from_results_dir,
    score_outcome,
    score_outcomes,
    stored_episodes,
)
from evaluator.runner.scenario import ScenarioOutcome, run_scenario
from evaluator.runner.score_cache import SCORES_FILE, ScoreCache
from evaluator.sandbox.backend_registry import backend_for, resolve_kind
from evaluator.sandbox.placement import claimed_cpus
from evaluator.sandbox.warm_pool import warm_agents
from evaluator.scoring import DEFAULT_PROFILE, ScoringProfile, load_profile
from evaluator.summary import (
    SUMMARY_FILE,
    EpisodeEntry,
    ScenarioEntry,
    Summary,
    read_summary,
    write_summary,
)
from evaluator.training import folder_digest
from sim.episode_workers import episode_workers
from submissions.intake import prepare_submission

TIMINGS_FILE = "timings.json"  # wall times: kept out of summary.json, which is deterministic
# Rewriting summary.json costs in proportion to the episodes it holds (60 to 100 us each; a
# DS-2022 run's 3,607 make a write a third of a second), and the evaluating thread holds the GIL
# while it encodes. Written after every episode, a long run spent time quadratic in its length
# there. A checkpoint therefore waits this many times the last write's cost after it: the
# writes stay under a twentieth of the run's time, however long it is.
CHECKPOINT_SPACING = 19


class ResultsDirError(ArenaError):
    """``out_dir`` holds results that cannot be resumed by this evaluation."""


class Progress(Protocol):
    def started(self, total: int, done: Sequence[ScenarioOutcome]) -> None:
        """``done``: the episodes a previous run of the same folder finished (resumed)."""

    def finished(self, outcome: ScenarioOutcome) -> None: ...


@dataclass(frozen=True)
class EvaluationRequest:
    """What to evaluate and how: one ``arena evaluate``.

    ``source``: the submission (a folder or a zip); ``suite_dir``: the scenario set, of which
    ``scenario_ids`` (all when None) run; results go to ``out_dir``. ``per_submission`` puts them
    in ``out_dir/<first 12 hex of the submission's sha256>``, so an edited agent gets a folder of
    its own; ``force`` discards the results already there. ``episodes_per_scenario`` episodes of
    each reactive scenario run (one of each replay); the episodes a previous run finished are
    kept, so raising it reuses them. When the first ``fail_fast_after`` episodes all end with the
    agent failing to start, the rest are not run (the summary stays incomplete): one error, not
    one per scenario. ``model_dir`` is a trained output (``arena train``) the policy reads as
    ARENA_MODEL_DIR; the results then belong to the submission and that model together. The
    agent acts under ``cpu_limits`` (default: the sandbox settings'); once the CPU its episodes
    used passes the evaluation's budget, the rest are not run (the summary stays incomplete, and
    ``agent_cpu.json`` says why). Up to ``jobs`` episodes run at once, with ``sandbox`` (None:
    the setting) and scored with ``profile``.
    """

    source: Path
    suite_dir: Path
    out_dir: Path
    scenario_ids: Sequence[str] | None = None
    jobs: int = 1
    sandbox: SandboxKind | None = None
    profile: str = DEFAULT_PROFILE
    per_submission: bool = False
    force: bool = False
    fail_fast_after: int | None = FAIL_FAST_AFTER
    episodes_per_scenario: int = 1
    model_dir: Path | None = None
    cpu_limits: CpuLimits | None = None


def evaluate(
    request: EvaluationRequest,
    *,
    intake: IntakeSettings,
    config: SandboxSettings,
    data_dir: Path,
    progress: Progress | None = None,
) -> Summary:
    """Run the episodes of ``request`` not yet finished in its ``out_dir`` and return the
    summary. ``intake`` and ``config``: the intake's limits and the sandbox's; ``data_dir``: the
    data folder (the requirements' cache, the sandboxes' owner)."""
    cpu_limits = request.cpu_limits or config.cpu_limits
    scoring_profile = load_profile(request.profile)
    sandbox = _usable_sandbox(request.sandbox, config)
    suite = load_suite(request.suite_dir).select(request.scenario_ids)
    out_dir = Path(request.out_dir)
    model_dir = request.model_dir
    allowed = os.sched_getaffinity(0)  # the CPUs the jobs share out (claimed_cpus)
    with tempfile.TemporaryDirectory(prefix="arena-submission-") as tmp:
        Path(tmp).chmod(0o755)  # sandboxes run the agent as another user, who must enter it
        submission = prepare_submission(
            Path(request.source), Path(tmp) / "submission", intake, config, data_dir
        )
        identity = submission.sha256
        if model_dir is not None:
            submission, identity = _with_model(submission, Path(model_dir))
        if request.per_submission:
            out_dir = out_dir / identity[:12]
        if request.force:
            discard_results(out_dir)
        (out_dir / RECORDS_DIR).mkdir(parents=True, exist_ok=True)
        (out_dir / LOGS_DIR).mkdir(exist_ok=True)
        pins = (submission.sha256, _model_digest(model_dir))
        run = ResultsFolder(
            out_dir,
            suite,
            scoring_profile,
            identity,
            request.episodes_per_scenario,
            pins,
            cpu_limits=cpu_limits,
        )
        todo = run.resume()
        if progress:
            progress.started(len(run.episodes), list(run.outcomes.values()))

        def play(episode: Episode, job: int) -> ScenarioOutcome:
            with claimed_cpus(job, config, allowed) as cpus:
                return run_scenario(
                    submission,
                    suite.scenario_dir(episode.scenario_id),
                    out_dir / RECORDS_DIR,
                    config=config,
                    data_dir=data_dir,
                    sandbox=sandbox,
                    episode=episode.index,
                    limits=cpu_limits,
                    cpus=cpus,
                )

        with (
            _warm_agents_of(submission),
            # Its simulator processes end with it, not an idle time later.
            episode_workers().serving(),
            ThreadPoolExecutor(max_workers=max(1, request.jobs)) as pool,
        ):
            pending: dict[Future, Episode] = {}
            # Which job (0 to jobs - 1) each running episode is: its CPUs are the job's.
            jobs_of: dict[Future, int] = {}
            queue = list(todo)
            starts = _StartWatch(request.fail_fast_after)
            finished: list[ScenarioOutcome] = []
            while True:
                while (
                    queue
                    and len(pending) < request.jobs
                    and not (starts.gave_up or run.over_budget)
                ):
                    episode = queue.pop(0)
                    run.mark_running(episode)
                    job = min(set(range(request.jobs)) - set(jobs_of.values()))
                    future = pool.submit(play, episode, job)
                    pending[future], jobs_of[future] = episode, job
                # The episodes that finished are scored (reading their records) while the next
                # ones start.
                for outcome in finished:
                    run.record(outcome)
                    if progress:
                        progress.finished(outcome)
                run.checkpoint()
                if not pending:
                    break
                done, _ = wait(pending, return_when=FIRST_COMPLETED)
                for future in done:
                    del jobs_of[future]
                finished = [_outcome_of(future, pending.pop(future)) for future in done]
                for outcome in finished:
                    starts.saw(outcome)
                    run.charge_cpu(outcome)  # before the next ones start, unlike the scoring
    return run.summary()


@contextmanager
def _warm_agents_of(submission) -> Iterator[None]:
    """The submission's warm agents close with its evaluation (its folder is about to go)."""
    try:
        yield
    finally:
        warm_agents().close(submission.sha256)


def _with_model(submission, model_dir: Path):
    """The submission reading ``model_dir``, and the identity of the pair (sha256 of both)."""
    if not model_dir.is_dir():
        raise ResultsDirError(f"the model folder {model_dir} does not exist (run `arena train`)")
    pair = hashlib.sha256(f"{submission.sha256}:{folder_digest(model_dir)}".encode())
    return dataclasses.replace(submission, model_dir=model_dir.resolve()), pair.hexdigest()


def _model_digest(model_dir: Path | None) -> str | None:
    from evaluator.training import folder_digest

    return folder_digest(Path(model_dir)) if model_dir is not None else None


def discard_results(out_dir: Path) -> None:
    """Remove what an evaluation wrote in ``out_dir`` (and nothing else a user keeps there)."""
    for name in (SUMMARY_FILE, TIMINGS_FILE, AGENT_CPU_FILE, SCORES_FILE):
        (out_dir / name).unlink(missing_ok=True)
    for folder in (RECORDS_DIR, LOGS_DIR):
        shutil.rmtree(out_dir / folder, ignore_errors=True)


class _StartWatch:
    """Gives up on a run whose first scenarios all show the agent unable to start."""

    def __init__(self, after: int | None) -> None:
        self.after = after
        self.seen = 0
        self.gave_up = False

    def saw(self, outcome: ScenarioOutcome) -> None:
        if self.after is None or self.seen < 0:
            return
        if outcome.status == ScenarioStatus.done and never_started(outcome.agents):
            self.seen += 1
            self.gave_up = self.seen >= self.after
        elif outcome.status == ScenarioStatus.done:
            self.seen = -1  # it started once: every scenario runs


def _usable_sandbox(kind: SandboxKind | None, config: SandboxSettings) -> SandboxKind:
    """The concrete sandbox, checked once: a missing daemon or tool fails the evaluation before
    any scenario, instead of every scenario failing on it."""
    kind = resolve_kind(kind, config)
    reason = backend_for(kind).unavailable_reason(config)
    if reason is not None:
        raise SandboxUnavailable(f"sandbox {kind.value} cannot run here: {reason}")
    return kind


def _outcome_of(future: Future, episode: Episode) -> ScenarioOutcome:
    """An exception from the runner itself (sandbox unavailable, a bug) is ours: the episode is
    reported uncharged with the traceback rather than ending the whole evaluation."""
    try:
        return future.result()
    except Exception as exc:
        return ScenarioOutcome.ours(
            episode.scenario_id,
            f"{type(exc).__name__}: {exc}",
            log="".join(traceback.format_exception(exc)),
            episode=episode.index,
        )


class ResultsFolder:
    """The results folder of one evaluation, written from the main thread and workers alike."""

    def __init__(
        self,
        out_dir: Path,
        suite: Suite,
        profile: ScoringProfile,
        submission: str,
        episodes_per_scenario: int = 1,
        pins: tuple[str, str | None] | None = None,
        *,
        cpu_limits: CpuLimits,
    ) -> None:
        """``pins``: the sha256 of the submission's zip and of its trained model (or None), for
        the reproducibility manifest (``submission`` is the identity of the pair);
        ``cpu_limits``: whose evaluation budget the agent's CPU is counted against."""
        self.out_dir = out_dir
        self.suite = suite
        self.profile = profile
        self.submission = submission
        self.pins = pins or (submission, None)
        self.previous: Manifest | None = None  # of the episodes a previous run finished
        self.episodes_per_scenario = episodes_per_scenario
        self.episodes = episodes_of(suite.scenarios, episodes_per_scenario)
        self.outcomes: dict[Episode, ScenarioOutcome] = {}
        self.running: set[Episode] = set()
        self.cache: dict[Episode, ScoredEntry] = {}
        self.scores = ScoreCache(out_dir, profile)  # the cache's copy on disk, for a resume
        self.timings: dict[str, float] = {}  # episode name -> wall time [s]
        self.cpu = CpuLedger(out_dir, cpu_limits)
        self.lock = threading.Lock()
        self._next_checkpoint = 0.0  # [s] monotonic() of the next due checkpoint

    @property
    def over_budget(self) -> bool:
        """The agent's episodes used more CPU than the evaluation's budget: start no more."""
        with self.lock:
            return self.cpu.over_budget

    def resume(self) -> list[Episode]:
        """Keep the episodes a previous run finished; return the ones still to run."""
        if (self.out_dir / SUMMARY_FILE).exists():
            previous = read_summary(self.out_dir)
            if (previous.submission, previous.manifest_hash) != (
                self.submission,
                self.suite.sha256,
            ):
                raise ResultsDirError(
                    f"{self.out_dir} holds results of another submission or suite "
                    f"(submission {previous.submission[:12]}, suite {previous.suite}); "
                    "use a fresh --out, or --force to replace them"
                )
            self.previous = previous.manifest
            kept = []
            for entry in previous.scenarios:
                for key, episode in stored_episodes(entry):
                    if is_finished(key, episode, self.out_dir):
                        self.outcomes[key] = outcome_from_results_dir(key, episode, self.out_dir)
                        kept.append((key, episode, entry.family))
            self._reuse_scores(kept)
            timings = self.out_dir / TIMINGS_FILE
            if timings.exists():
                self.timings = json.loads(timings.read_text())
        # Episodes beyond the ones now asked for are dropped, not reported.
        self.outcomes = {k: o for k, o in self.outcomes.items() if k in set(self.episodes)}
        self._write()
        return [e for e in self.episodes if e not in self.outcomes]

    def _reuse_scores(self, kept: list[tuple[Episode, ScenarioEntry | EpisodeEntry, str]]) -> None:
        """Take the scores of the ``kept`` episodes (key, stored entry, family) that the score
        cache holds for this profile and their records as they are, instead of re-reading them."""
        records = {key.name: self.outcomes[key].record_path for key, _, _ in kept}
        known = self.scores.load(records)
        for key, episode, family in kept:
            score = known.get(key.name)
            if score is not None:  # kept episodes are done ones (is_finished)
                self.cache[key] = done_entry(
                    key.scenario_id, family, episode.steps, episode.agents, score
                )

    def mark_running(self, episode: Episode) -> None:
        """``episode`` started (written with the next :meth:`summary`)."""
        with self.lock:
            self.running.add(episode)

    def charge_cpu(self, outcome: ScenarioOutcome) -> None:
        """Count the CPU ``outcome``'s agent used against the evaluation's budget (written with
        the next :meth:`summary`)."""
        with self.lock:
            self.cpu.charge(outcome.key.name, outcome.agent_cpu_s)

    def record(self, outcome: ScenarioOutcome) -> None:
        """``episode`` finished: its log now, its entry with the next :meth:`summary`."""
        with self.lock:
            key = outcome.key
            self.running.discard(key)
            scenario = next(s for s in self.suite.scenarios if s.id == outcome.scenario_id)
            scored = score_outcome(scenario, outcome, self.profile)
            self.outcomes[key] = outcome
            self.cache[key] = scored
            self.timings[key.name] = round(outcome.wall_time_s, 3)
            log = storable_text(outcome.log)  # the agent's text: any code point
            write_atomically(self.out_dir / LOGS_DIR / f"{key.name}.txt", log)

    def _manifest(self) -> Manifest:
        """The manifest of the finished episodes; those a previous run finished keep the seeds
        and environments it recorded."""
        before = self.previous.scenarios if self.previous is not None else {}

        def seed(outcome: ScenarioOutcome) -> int | None:
            if outcome.seed is not None:
                return outcome.seed
            seeds = before[outcome.scenario_id].seeds if outcome.scenario_id in before else ()
            return seeds[outcome.episode] if outcome.episode < len(seeds) else None

        manifest = manifest_of(
            self.suite,
            [
                EpisodeRun(o.scenario_id, o.episode, seed(o), o.environment)
                for o in self.outcomes.values()
            ],
            submission=self.pins[0],
            model=self.pins[1],
            episodes_per_scenario=self.episodes_per_scenario,
            profile=self.profile.name,
            profile_version=str(self.profile.version),
        )
        if self.previous is None:
            return manifest
        environments = distinct([*self.previous.environments, *manifest.environments])
        return manifest.model_copy(update={"environments": environments})

    def summary(self) -> Summary:
        """Write ``summary.json`` (and the timings) as they are now, and return the summary."""
        with self.lock:
            return self._write()

    def checkpoint(self) -> None:
        """:meth:`summary`, unless the last write was too recent for its cost
        (:data:`CHECKPOINT_SPACING`)."""
        if monotonic() >= self._next_checkpoint:
            self.summary()

    def _write(self) -> Summary:
        started = monotonic()
        summary = score_outcomes(
            self.outcomes.values(),
            self.suite,
            self.profile,
            submission=self.submission,
            episodes_per_scenario=self.episodes_per_scenario,
            running=self.running,
            cache=self.cache,
        )
        summary = summary.model_copy(update={"manifest": self._manifest()})
        write_summary(summary, self.out_dir)
        self.scores.write(
            {
                key.name: (score, self.outcomes[key].record_path)
                for key, (_, score) in self.cache.items()
                if score is not None and key in self.outcomes
            }
        )
        write_atomically(self.out_dir / TIMINGS_FILE, json.dumps(self.timings, indent=2) + "\n")
        self.cpu.write()
        ended = monotonic()
        self._next_checkpoint = ended + CHECKPOINT_SPACING * (ended - started)
        return summary
