"""One scenario for one submission: a sandboxed agent driving in its own simulator process."""

from __future__ import annotations

import dataclasses
import time
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from arena.config import SandboxKind, SandboxSettings
from arena.cpu_limits import CpuLimits
from arena.episodes import Episode, traffic_seed
from arena.outcome import UNCHARGED, AgentOutcome, ScenarioStatus, Verdict, episode_verdict
from arena.record_format import RECORD_SUFFIX
from arena.scenario import load_scenario
from evaluator import sandbox as sandboxes
from evaluator.failures import describe_end
from evaluator.provenance import Environment, environment
from evaluator.sandbox.placement import pin_process
from evaluator.sandbox.warm_pool import warm_agents
from sim.episode_workers import episode_workers

if TYPE_CHECKING:
    from evaluator.sandbox.warm import ForkedAgent
    from sim.agent import Agent
    from sim.result import EpisodeResult
    from submissions.intake import PreparedSubmission

# SUMO failures are usually transient (a crashed or stuck libsumo); one more try, then it is
# reported as ours and not charged.
SIMULATOR_ATTEMPTS = 2


@dataclass(frozen=True)
class SandboxedAgentFactory:
    """Picklable: the simulator's child process calls it to start the agent in its sandbox. The
    process that calls it (the episode's simulator) moves to ``cpus``, where the sandbox starts
    too (the job's, :mod:`evaluator.sandbox.placement`; None: wherever the scheduler puts them).
    """

    submission: PreparedSubmission
    kind: SandboxKind | None
    labels: dict[str, str]
    config: SandboxSettings
    data_dir: Path
    limits: CpuLimits | None = None
    cpus: tuple[int, ...] | None = None

    def __call__(self) -> Agent:
        pin_process(self.cpus)
        return sandboxes.start(
            self.submission,
            config=self.config,
            data_dir=self.data_dir,
            kind=self.kind,
            labels=self.labels,
            limits=self.limits,
            cpus=self.cpus,
        )

    @property
    def preload_modules(self) -> tuple[str, ...]:
        """Imported once by the simulator's fork server instead of in every episode's process
        (see :func:`sim.isolation.preload_modules`)."""
        return ("evaluator.sandbox", *sandboxes.client_modules(self.kind))


@dataclass(frozen=True)
class ForkedAgentFactory:
    """Picklable: the simulator's child process calls it to take over the agent forked for this
    episode in the submission's warm sandbox (:mod:`evaluator.sandbox.warm`), whose zygote runs
    on ``cpus``; the process that calls it moves there too, as with
    :class:`SandboxedAgentFactory`."""

    agent: ForkedAgent
    limits: CpuLimits | None = None
    cpus: tuple[int, ...] | None = None

    def __call__(self) -> Agent:
        pin_process(self.cpus)
        return self.agent.start(self.limits)

    preload_modules = ("evaluator.sandbox.warm",)


@contextmanager
def agent_factory(
    submission: PreparedSubmission,
    kind: SandboxKind,
    labels: dict[str, str],
    config: SandboxSettings,
    data_dir: Path,
    limits: CpuLimits | None = None,
    cpus: tuple[int, ...] | None = None,
) -> Iterator[SandboxedAgentFactory | ForkedAgentFactory]:
    """How one episode gets its agent: forked in a warm sandbox when the setting allows and the
    submission's zygote started, else in a sandbox of its own; either acts under ``limits`` and
    runs on ``cpus`` with the episode's simulator."""
    cold = SandboxedAgentFactory(submission, kind, labels, config, data_dir, limits, cpus)
    if not config.warm_agents:
        yield cold
        return
    with warm_agents().lease(submission, kind, labels, config, data_dir, cpus) as forked:
        if forked is None:
            yield cold
        else:
            yield ForkedAgentFactory(forked, limits, cpus)


@dataclass(frozen=True)
class ScenarioOutcome:
    """How one episode of a scenario ended."""

    scenario_id: str
    status: ScenarioStatus  # done, simulator_error or evaluator_error
    steps: int  # episode steps simulated
    agents: tuple[AgentOutcome, ...]
    record_path: Path | None  # None when no agent drove a step, or on an uncharged error
    error: str | None = None  # why an uncharged scenario failed
    log: str = ""  # agent stderr tail and failure detail, for the participant
    attempts: int = 1
    wall_time_s: float = 0.0
    episode: int = 0  # which episode of the scenario (arena.episodes)
    seed: int | None = None  # the SUMO traffic seed it ran with
    environment: Environment | None = None  # the software it ran under (evaluator.provenance)
    # The CPU time the agent used from its loading [s] (0 where no meter reads it): what the
    # evaluation's budget counts. Only the attempt that counts is charged, never one that failed
    # on our side.
    agent_cpu_s: float = 0.0
    # Whether its agent was sent an observation (False: it failed while it was loaded).
    observed: bool = True

    @property
    def key(self) -> Episode:
        return Episode(self.scenario_id, self.episode)

    @property
    def verdict(self) -> Verdict:
        """Whose its end is (:func:`arena.outcome.verdict`): an uncharged status is ours."""
        if self.status in UNCHARGED:
            return Verdict.ours
        return episode_verdict(a.reason for a in self.agents)

    @classmethod
    def ours(
        cls, scenario_id: str, error: str, *, log: str = "", attempts: int = 1, episode: int = 0
    ):
        """A scenario that could not be evaluated through no fault of the submission."""
        return cls(
            scenario_id=scenario_id,
            episode=episode,
            status=ScenarioStatus.evaluator_error,
            steps=0,
            agents=(),
            record_path=None,
            error=error,
            log=log,
            attempts=attempts,
        )


def new_run_key() -> str:
    """An opaque key for one run of one scenario: unique, and identifying no scenario (labels
    reach the sandbox's environment under bubblewrap, and hidden scenario ids must not)."""
    return uuid.uuid4().hex


def sandbox_labels(run_key: str, attempt: int | None = None) -> dict[str, str]:
    """The labels on the sandbox of one attempt (``attempt``) of one scenario run (``run_key``,
    from :func:`new_run_key`); without ``attempt``, those every attempt of the run carries.
    ``evaluator.sandbox.cleanup(config, labels)`` removes what a dead episode left behind, and
    only that: labels never depend on the zip's content, which two teams can share."""
    labels = {"arena.run": run_key}
    if attempt is not None:
        labels["arena.attempt"] = str(attempt)
    return labels


def run_scenario(
    submission: PreparedSubmission,
    scenario_dir: Path,
    records_dir: Path,
    *,
    config: SandboxSettings,
    data_dir: Path,
    sandbox: SandboxKind | None = None,
    run_key: str | None = None,
    episode: int = 0,
    limits: CpuLimits | None = None,
    cpus: tuple[int, ...] | None = None,
) -> ScenarioOutcome:
    """Simulate episode ``episode`` of ``scenario_dir`` (its traffic seed from
    :func:`arena.episodes.traffic_seed`) with the submission's agent, writing
    ``records_dir/<episode name>.npz``; a simulator error is retried once.

    Agent failures come back as a ``done`` outcome whose agents carry the reason. Infrastructure
    errors (sandbox unavailable) are raised so the caller can retry the job. ``run_key`` labels
    the sandboxes (:func:`sandbox_labels`); a fresh one is made when not given. The agent runs
    in a sandbox of ``config`` (``sandbox``: its kind, None: the setting's) owned by
    ``data_dir``, and acts under ``limits`` (default: ``config``'s); the outcome says the CPU
    it used. The episode's simulator and agent run on ``cpus`` (its job's,
    held by :func:`evaluator.sandbox.placement.claimed_cpus`; None: wherever the scheduler
    puts them).
    """
    kind = sandboxes.resolve_kind(sandbox, config)
    scenario = load_scenario(scenario_dir)
    key = Episode(scenario.id, episode)
    record_path = Path(records_dir) / f"{key.name}{RECORD_SUFFIX}"
    record_path.parent.mkdir(parents=True, exist_ok=True)
    run_key = run_key or new_run_key()
    seed = traffic_seed(scenario.id, scenario.seed, episode)
    started = time.monotonic()
    logs = []
    for attempt in range(1, SIMULATOR_ATTEMPTS + 1):
        labels = sandbox_labels(run_key, attempt)
        record_path.unlink(missing_ok=True)
        with agent_factory(submission, kind, labels, config, data_dir, limits, cpus) as factory:
            result = episode_workers().run_episode(
                scenario_dir,
                factory,
                submission.interface,
                record_path=record_path,
                seed=seed,
                episode_timeout_s=config.episode_timeout_s,
            )
        logs.append(_log_text(result, attempt, key))
        reasons = [a.reason for a in result.agents]
        simulator_failed = result.simulator_error is not None
        if episode_verdict(reasons, simulator_failed=simulator_failed) is not Verdict.ours:
            return dataclasses.replace(
                _outcome(result, record_path, "\n".join(logs), attempt, started, episode),
                seed=seed,
                environment=environment(
                    kind.value, config.agent_image, result.extra.get("agent_stack", {})
                ),
            )
        # Ours (arena.outcome.verdict): the episode's process died or SUMO failed while the
        # agent was healthy, or a sandbox ended before our runner said hello in it (killed from
        # outside, the daemon failed). The episode runs again; its agent's sandbox may never
        # have been closed.
        sandboxes.cleanup(config, labels)
    record_path.unlink(missing_ok=True)
    if result.simulator_error is None:
        return ScenarioOutcome.ours(
            scenario.id,
            "an agent's sandbox ended or stayed silent before the runner started in it, on every "
            "attempt",
            log="\n".join(logs),
            attempts=SIMULATOR_ATTEMPTS,
            episode=episode,
        )
    return ScenarioOutcome(
        scenario_id=scenario.id,
        status=ScenarioStatus.simulator_error,
        steps=result.steps,
        agents=(),
        record_path=None,
        error=result.simulator_error,
        log="\n".join(logs),
        attempts=SIMULATOR_ATTEMPTS,
        wall_time_s=time.monotonic() - started,
        episode=episode,
    )


def _outcome(
    result: EpisodeResult,
    record_path: Path,
    log: str,
    attempts: int,
    started: float,
    episode: int,
) -> ScenarioOutcome:
    return ScenarioOutcome(
        scenario_id=result.scenario_id,
        status=ScenarioStatus.done,
        steps=result.steps,
        agents=result.agents,
        record_path=record_path if record_path.exists() else None,
        log=log,
        attempts=attempts,
        wall_time_s=time.monotonic() - started,
        episode=episode,
        agent_cpu_s=result.agent_cpu_s,
        observed=result.observed,
    )


def _log_text(result: EpisodeResult, attempt: int, key: Episode) -> str:
    shown = key.scenario_id if key.index == 0 else f"{key.scenario_id} episode {key.index}"
    parts = [f"--- attempt {attempt}: {shown}"]
    if result.simulator_error:
        parts.append(f"simulator error: {result.simulator_error}")
    for agent in result.agents:
        parts.append(describe_end(agent))
    if result.detail:
        parts.append(result.detail)
    agent_log = result.extra.get("agent_log")
    if agent_log:
        parts.append("--- agent stderr (tail)\n" + str(agent_log))
    return "\n".join(parts)
