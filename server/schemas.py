"""API shapes (pydantic). Database tables are in :mod:`server.models`."""

from __future__ import annotations

from datetime import datetime
from typing import Literal

from pydantic import BaseModel, ConfigDict

from evaluator.provenance import PublicManifest
from server.status import RunStatus, SubmissionStatus, TrainingStatus
from server.tracks import Track


class Schema(BaseModel):
    model_config = ConfigDict(frozen=True, from_attributes=True)


class Metrics(Schema):
    """The four errors of the scoring spec; smaller is better."""

    completion: float
    time: float  # [steps]
    humanness: float | None  # None: no agent drove a step, nothing was measured
    rules: float | None


class FamilyMetrics(Metrics):
    scenarios: int


class CompletionInterval(Schema):
    """The 95% bootstrap confidence interval of completion (docs/scoring.md)."""

    low: float
    high: float


class SeedMetrics(Metrics):
    """One seed's own metrics (its trained model's run)."""

    seed: int


class SeedResults(Schema):
    """A submission trained with several seeds (docs/training.md): its metrics are the means
    over them, its completion interval covers seeds x scenarios; the seeds' own completion
    errors spread from ``completion_min`` to ``completion_max`` (standard deviation
    ``completion_std``)."""

    count: int
    completion_min: float
    completion_max: float
    completion_std: float
    per_seed: list[SeedMetrics]
    # Seeds whose trained outputs are byte-identical (train.py ignored ARENA_TRAIN_SEED), and
    # that said in words ("" when every seed trained its own model).
    identical_models: list[list[int]] = []
    ignores_seed: str = ""


class SeedFailureReasons(Schema):
    """One training seed's run: family -> failure reason -> number of episodes."""

    seed: int
    failure_reasons: dict[str, dict[str, int]]


class Progress(Schema):
    done: int
    total: int  # episodes: one per scenario, episodes_per_scenario per reactive scenario
    # "quarters": a hidden phase's run under way, told in quarters of it (done of total=4) whatever
    # its size (server/services/hidden_timing.py); "episodes" otherwise.
    unit: Literal["episodes", "quarters"] = "episodes"
    # Over several training seeds, every seed's run together (a seed still training counts
    # the episodes its run will have).
    seeds: int = 1


class SubmissionSummary(Schema):
    id: int
    team: str
    phase: str
    track: Track
    method_name: str
    status: SubmissionStatus
    created_at: datetime
    queued_at: datetime | None = None
    started_at: datetime | None = None  # the first evaluation (or training) began
    finished_at: datetime | None = None
    # [s] from start to finish, or so far while it trains or runs; None before it starts. In a
    # hidden phase: None until it ended, then rounded up to 10 minutes, and no finished_at
    # (server/services/hidden_timing.py).
    duration_s: float | None = None
    progress: Progress
    metrics: Metrics | None
    # None until scored (and for scores from before intervals existed).
    completion_interval: CompletionInterval | None
    episodes_per_scenario: int
    # Scored over several training seeds: their spread (None for one seed and freestyle).
    seeds: SeedResults | None = None


class TrainingProgress(Schema):
    """The training job of an offline submission shown (of its latest seed set: a failed seed,
    else one still under way, else the last). Its log is the team's to read: the dataset it
    trains on is public."""

    attempt: int  # the submission's training jobs in order, one per seed: not a retry count
    seed: int = 0  # ARENA_TRAIN_SEED
    seeds: int = 1  # of its seed set (the phase's training seeds)
    seed_set: int = 1  # the submission's seed sets in order: 2 and on, a retraining
    status: TrainingStatus
    elapsed_s: float
    log_tail: str
    failure: str  # a named failure (e.g. train_timeout), "" unless it failed
    error: str
    model_sha256: str  # of the stored trained output, once trained
    model_size: int  # [bytes]


class CpuLimitsView(Schema):
    """The agent's CPU time limits [s] in a phase (docs/protocol.md, "Time limits")."""

    step_s: float  # one act
    episode_s: float  # every act of one episode
    evaluation_s: float  # every episode of one evaluation: past it, the rest are not run


class AgentCpu(Schema):
    """The CPU time the agent used in the shown evaluation, against its budget [s]. Over several
    training seeds, each seed's model is its own evaluation with its own budget: ``used_s`` sums
    them, ``most_used_s`` is the most one of them used, which is what a budget stops."""

    used_s: float
    budget_s: float
    evaluations: int = 1
    most_used_s: float


class PhaseWindow(Schema):
    """The phase a submission was made in, as its team sees it."""

    name: str
    visibility: str  # full: everything per scenario; hidden: metrics and counts only
    starts_at: datetime | None  # None: open from the start
    ends_at: datetime | None  # None: never closes
    state: str  # "open", "closed" or "not yet open"
    # What the team does not see in this phase, and why ("" in a phase of full visibility).
    hidden: str
    cpu_limits: CpuLimitsView


class Standing(Schema):
    """Where the team stands in the submission's phase and track."""

    # The team's place on the leaderboard (its best scored submission); None: not ranked yet.
    rank: int | None
    teams_ranked: int
    ranked_submission_id: int | None  # the team's submission that holds that place
    # The entry's rank range and chance to beat the entry below, as on the leaderboard; tied_with
    # the other ranks in the range (None / empty: not ranked yet).
    rank_low: int | None = None
    rank_high: int | None = None
    rank_range: str | None = None
    beats_next: float | None = None
    compared: bool = True
    tied_with: list[int]
    statistics: str = ""  # the above in words, as the leaderboard and the CLI say them
    tries_left_today: int  # uploads left in this phase and track until 00:00 UTC
    daily_quota: int


class Allowance(Schema):
    """Uploads a team has left today in one phase and track."""

    phase: PhaseWindow
    track: Track
    tries_left_today: int
    daily_quota: int


class TeamStatus(Schema):
    """The caller's team and what it may still upload today, per phase and track."""

    team: str
    allowances: list[Allowance]


class Attempt(Schema):
    """A simulation attempt (an organiser's re-run is a new one) as its team may see it."""

    attempt: int
    status: RunStatus  # queued, running, scored, failed, cancelled
    # Why it failed, in the team's words ("" otherwise); a failure on our side says so.
    error: str


class SubmissionDetail(SubmissionSummary):
    description: str
    status_reason: str
    file_sha256: str
    file_size: int  # [bytes]
    attempt: int  # of the run whose score stands (or, before any score, the latest)
    # The latest attempt, whatever the score shown: a re-run under way, or one that failed
    # while the earlier score still stands. None before the first evaluation starts.
    latest_attempt: Attempt | None = None
    scoring_profile: str | None
    families: dict[str, FamilyMetrics]
    # family -> failure reason -> number of episodes (of scenarios, when each ran once). Scenario
    # ids of the hidden suite are never shown to participants; these counts are.
    # Over several training seeds: summed over every seed's run (each seed's in
    # seed_failure_reasons).
    failure_reasons: dict[str, dict[str, int]]
    seed_failure_reasons: list[SeedFailureReasons] = []  # one per seed; empty for one run
    training: TrainingProgress | None = None  # offline (Track 2) submissions
    # Of the run whose progress is shown; None before it starts.
    agent_cpu: AgentCpu | None = None
    phase_window: PhaseWindow | None = None
    standing: Standing | None = None
    # The score's reproducibility manifest as the team may see it (evaluator/provenance.py
    # Manifest.public: no hidden scenario ids or seeds); None before a score, or for a score
    # written before manifests existed.
    manifest: PublicManifest | None = None


class ScenarioLog(Schema):
    label: str  # "<family> #<k>", plus " episode <e>" when scenarios ran several times
    scenario_id: str  # only ever shown where the suite is public to the reader
    episode: int
    family: str
    status: str
    reason: str
    log_tail: str


class SubmissionLogs(Schema):
    submission_id: int
    scenarios: list[ScenarioLog]


class GeneralisationGap(Schema):
    phase: str  # the phase compared with
    submission_id: int  # the team's entry there
    metrics: Metrics  # that entry's metrics
    difference: Metrics  # this entry's minus those (None where either is not measured)


class LeaderboardEntry(Schema):
    rank: int
    team: str
    submission_id: int
    method_name: str
    submitted_at: datetime
    metrics: Metrics
    completion_interval: CompletionInterval | None
    # Ranks this entry could hold: entries whose difference is not significant share them
    # (docs/scoring.md, "Rank ranges"); rank_range is "2-4", or "3" when the rank is certain.
    # tied_with: the other ranks in that range, the entries it is statistically tied with.
    tied_with: list[int]
    rank_low: int
    rank_high: int
    rank_range: str
    # The chance this entry ranks ahead of the entry just below it over the bootstrap
    # resamples; None for the last entry and next to a score without per-episode values.
    beats_next: float | None
    # False: scored before per-episode values were kept; never compared, its rank its position.
    compared: bool = True
    episodes_per_scenario: int
    families: dict[str, FamilyMetrics]
    seeds: SeedResults | None = None  # scored over several training seeds
    # With ?gap_from=PHASE: this entry's metrics minus its team's entry in that phase (positive:
    # worse here, e.g. on the hidden suite than on the public one); None without one there.
    gap: GeneralisationGap | None = None


class Leaderboard(Schema):
    phase: str
    track: Track
    entries: list[LeaderboardEntry]
    gap_from: str | None = None  # the phase the generalisation gaps are measured against


class PublicScenario(Schema):
    id: str
    family: str
    variant: str
    volume: str | None
    agents: int
    reactive: bool


class Health(Schema):
    status: str
    database: bool
    broker: bool
