"""Database tables (SQLAlchemy 2.0 typed ORM). API shapes live in :mod:`server.schemas`.

Alembic autogenerates migrations from :data:`Base.metadata`; every schema change is a migration.
"""

from __future__ import annotations

from datetime import UTC, datetime
from enum import StrEnum
from typing import Any

from sqlalchemy import (
    JSON,
    BigInteger,
    DateTime,
    Enum,
    Float,
    ForeignKey,
    Index,
    Integer,
    LargeBinary,
    MetaData,
    String,
    Text,
    TypeDecorator,
    UniqueConstraint,
    false,
    text,
)
from sqlalchemy.ext.hybrid import hybrid_property
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column, relationship

from arena.outcome import ScenarioStatus
from server.jobs.rows import LeasedJob
from server.status import RunStatus, SubmissionStatus, TrainingStatus
from server.tracks import Track


def utcnow() -> datetime:
    return datetime.now(UTC)


# Stable constraint names so Alembic migrations are identical on SQLite and PostgreSQL.
NAMING = {
    "ix": "ix_%(column_0_label)s",
    "uq": "uq_%(table_name)s_%(column_0_name)s",
    "ck": "ck_%(table_name)s_%(constraint_name)s",
    "fk": "fk_%(table_name)s_%(column_0_name)s_%(referred_table_name)s",
    "pk": "pk_%(table_name)s",
}


class UTCDateTime(TypeDecorator):
    """Timezone-aware UTC datetimes on every backend (SQLite hands back naive ones)."""

    impl = DateTime(timezone=True)
    cache_ok = True

    def process_bind_param(self, value: datetime | None, dialect) -> datetime | None:
        return value.astimezone(UTC) if value is not None else None

    def process_result_value(self, value: datetime | None, dialect) -> datetime | None:
        if value is not None and value.tzinfo is None:
            return value.replace(tzinfo=UTC)
        return value


class Base(DeclarativeBase):
    metadata = MetaData(naming_convention=NAMING)
    type_annotation_map = {datetime: UTCDateTime(), dict[str, Any]: JSON}  # noqa: RUF012


def _enum(cls: type[StrEnum]) -> Enum:
    # Stored as plain strings (no native PG enum): adding a value needs no type migration.
    return Enum(cls, native_enum=False, length=16, validate_strings=True)


class Team(Base):
    __tablename__ = "teams"

    id: Mapped[int] = mapped_column(primary_key=True)
    name: Mapped[str] = mapped_column(String(64), unique=True)
    created_at: Mapped[datetime] = mapped_column(default=utcnow)

    tokens: Mapped[list[ApiToken]] = relationship(back_populates="team")


class ApiToken(Base):
    """A team's bearer token, stored as the sha256 of the secret; revoked on rotation."""

    __tablename__ = "api_tokens"

    id: Mapped[int] = mapped_column(primary_key=True)
    team_id: Mapped[int] = mapped_column(ForeignKey("teams.id"), index=True)
    token_sha256: Mapped[str] = mapped_column(String(64), unique=True)
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
    revoked_at: Mapped[datetime | None]

    team: Mapped[Team] = relationship(back_populates="tokens")


class Visibility(StrEnum):
    """What a team sees of its own evaluation in a phase."""

    # Validation on the public scenarios: per-scenario results, the agent's output, records.
    full = "full"
    # The hidden suite: the four metrics, per-family figures and per-family failure counts only;
    # no byte the agent wrote reaches the team (the organisers see it).
    hidden = "hidden"


class Phase(Base):
    """A phase of the competition: which suite, when uploads are open, the daily quota per team
    and track, what teams may see. Migration 0003 creates the default two, open-ended."""

    __tablename__ = "phases"

    id: Mapped[int] = mapped_column(primary_key=True)
    name: Mapped[str] = mapped_column(String(32), unique=True)
    # `public`, `hidden` (the configured suites) or a suite folder.
    suite: Mapped[str] = mapped_column(String(512))
    visibility: Mapped[Visibility] = mapped_column(_enum(Visibility))
    starts_at: Mapped[datetime | None]  # None: open from the start
    ends_at: Mapped[datetime | None]  # None: never closes
    daily_quota: Mapped[int | None] = mapped_column(Integer)  # None: the setting's daily_quota
    scoring_profile: Mapped[str | None] = mapped_column(String(64))  # None: the setting's
    # Episodes of each reactive scenario (arena/episodes.py); None: the setting's.
    episodes_per_scenario: Mapped[int | None] = mapped_column(Integer)
    # Adaptive evaluation (docs/scoring.md): rounds of episodes_per_scenario more episodes until
    # completion's 95% interval has a half-width at most adaptive_target, up to max_episodes per
    # reactive scenario. None: a fixed count.
    adaptive_target: Mapped[float | None] = mapped_column(Float)
    max_episodes: Mapped[int | None] = mapped_column(Integer)
    # When the organisers released the closed phase (arena admin phases release): its suite is
    # downloadable and every team sees its own episodes. None: nothing changes.
    released_at: Mapped[datetime | None]
    # The agent's CPU limits [s] (arena/cpu_limits.py): an act's, an episode's, an evaluation's.
    # None: the setting's (step_cpu_s, episode_cpu_s, evaluation_cpu_s).
    step_cpu_s: Mapped[float | None] = mapped_column(Float)
    episode_cpu_s: Mapped[float | None] = mapped_column(Float)
    evaluation_cpu_s: Mapped[float | None] = mapped_column(Float)
    # Track 2: each offline submission is trained this many times, each with its own seed
    # (ARENA_TRAIN_SEED 0..N-1), and scored over them (evaluator/scoring/seeds.py).
    training_seeds: Mapped[int] = mapped_column(Integer, default=1, server_default="1")


class Submission(Base):
    __tablename__ = "submissions"
    __table_args__ = (
        Index("ix_submissions_team_track_created", "team_id", "track", "created_at"),
        # A team has at most one upload being validated: the quota slot it reserves is taken
        # atomically, whatever the number of parallel uploads (migration 0010).
        Index(
            "uq_submissions_one_validating_per_team",
            "team_id",
            unique=True,
            postgresql_where=text("status = 'validating'"),
            sqlite_where=text("status = 'validating'"),
        ),
    )

    id: Mapped[int] = mapped_column(primary_key=True)
    team_id: Mapped[int] = mapped_column(ForeignKey("teams.id"))
    phase: Mapped[str] = mapped_column(
        String(32), ForeignKey("phases.name"), default="final", server_default="final", index=True
    )
    track: Mapped[Track] = mapped_column(_enum(Track))
    method_name: Mapped[str] = mapped_column(String(128))
    description: Mapped[str] = mapped_column(Text, default="")
    file_sha256: Mapped[str] = mapped_column(String(64))
    file_size: Mapped[int] = mapped_column(BigInteger)
    # The zip in the artifact store (server/core/artifacts.py).
    upload_key: Mapped[str] = mapped_column(String(512))
    # Its requirements' folder (submissions/intake/dependencies.py), set by the validation; a
    # folder no kept submission names is deleted.
    deps_key: Mapped[str | None] = mapped_column(String(64))
    status: Mapped[SubmissionStatus] = mapped_column(_enum(SubmissionStatus), index=True)
    status_reason: Mapped[str] = mapped_column(Text, default="")
    # Failed through no fault of the team (our scenarios failed): the one failure that gives the
    # daily quota back. Everything else counts from the moment the upload is accepted.
    failed_on_our_side: Mapped[bool] = mapped_column(default=False, server_default=false())
    # Its run stopped early because its agent could not be loaded (import, __init__): nothing of
    # a scenario reached it, so it gives the daily quota back too (docs/submissions.md).
    never_started: Mapped[bool] = mapped_column(default=False, server_default=false())
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
    queued_at: Mapped[datetime | None]
    # Set when the first evaluation starts: a submission cancelled before it does not count
    # towards the daily quota.
    started_at: Mapped[datetime | None]
    finished_at: Mapped[datetime | None]

    team: Mapped[Team] = relationship()
    runs: Mapped[list[EvaluationRun]] = relationship(
        back_populates="submission", order_by="EvaluationRun.attempt"
    )
    trainings: Mapped[list[TrainingJob]] = relationship(
        back_populates="submission", order_by="TrainingJob.attempt"
    )
    seed_set_scores: Mapped[list[SeedSetScore]] = relationship(
        back_populates="submission", order_by="SeedSetScore.attempt"
    )


class UploadValidation(LeasedJob, Base):
    """The job validating an upload (``agent_runtime/intake.py`` in the sandbox), while its
    submission is ``validating``: under way until its verdict is written."""

    __tablename__ = "upload_validations"

    id: Mapped[int] = mapped_column(primary_key=True)
    submission_id: Mapped[int] = mapped_column(ForeignKey("submissions.id"), unique=True)
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
    started_at: Mapped[datetime | None]
    finished_at: Mapped[datetime | None]
    # Worker time [s] its claims have held so far (the team's validation budget pays it), and
    # when the current claim took it.
    used_s: Mapped[float] = mapped_column(Float, default=0.0, server_default="0")
    claimed_at: Mapped[datetime | None]

    submission: Mapped[Submission] = relationship()

    @hybrid_property
    def under_way(self) -> bool:
        return self.finished_at is None

    @under_way.inplace.expression
    @classmethod
    def _under_way_expression(cls):
        return cls.finished_at.is_(None)


class TrainingJob(LeasedJob, Base):
    """One attempt at training an offline (Track 2) submission: its ``train.py`` in the sandbox,
    then the trained output in the artifact store with its sha256. A job of the engine: a worker
    that dies while training stops renewing the lease and the reaper sends the job again."""

    __tablename__ = "training_jobs"
    __table_args__ = (UniqueConstraint("submission_id", "attempt"),)

    id: Mapped[int] = mapped_column(primary_key=True)
    submission_id: Mapped[int] = mapped_column(ForeignKey("submissions.id"), index=True)
    attempt: Mapped[int] = mapped_column(Integer)
    status: Mapped[TrainingStatus] = mapped_column(_enum(TrainingStatus), index=True)
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
    started_at: Mapped[datetime | None]
    finished_at: Mapped[datetime | None]
    # Progress the team sees (the dataset is public, so the log is theirs to read).
    elapsed_s: Mapped[float] = mapped_column(Float, default=0.0)
    log_tail: Mapped[str] = mapped_column(Text, default="")
    # A named failure (evaluator.training.TrainFailure) or one of ours; "" while it runs or after
    # it trained.
    failure: Mapped[str] = mapped_column(String(32), default="")
    error: Mapped[str] = mapped_column(Text, default="")
    # The trained output in the artifact store: a deterministic .tar.gz and its sha256.
    model_key: Mapped[str | None] = mapped_column(String(512))
    model_sha256: Mapped[str] = mapped_column(String(64), default="")
    model_size: Mapped[int] = mapped_column(BigInteger, default=0)
    # The trainings started together, one per seed (the phase's training_seeds): numbered per
    # submission; each job of a set has its own seed (ARENA_TRAIN_SEED) and knows the set's size.
    seed_set: Mapped[int] = mapped_column(Integer, default=1, server_default="1")
    seed: Mapped[int] = mapped_column(Integer, default=0, server_default="0")
    seeds: Mapped[int] = mapped_column(Integer, default=1, server_default="1")

    submission: Mapped[Submission] = relationship(back_populates="trainings")

    @hybrid_property
    def under_way(self) -> bool:  # claimed: a queued one has no holder to fence
        return self.status == TrainingStatus.training


class EvaluationRun(Base):
    """One attempt at simulating a submission on the evaluation suite."""

    __tablename__ = "evaluation_runs"
    __table_args__ = (UniqueConstraint("submission_id", "attempt"),)

    id: Mapped[int] = mapped_column(primary_key=True)
    submission_id: Mapped[int] = mapped_column(ForeignKey("submissions.id"), index=True)
    attempt: Mapped[int] = mapped_column(Integer)
    status: Mapped[RunStatus] = mapped_column(_enum(RunStatus), index=True)
    suite_dir: Mapped[str] = mapped_column(String(512))
    manifest_sha256: Mapped[str] = mapped_column(String(64))
    # Episodes to run: one per scenario, episodes_per_scenario per reactive scenario.
    episode_count: Mapped[int] = mapped_column(Integer)
    # Fixed when the run is made: a later change to the phase does not change a run under way.
    episodes_per_scenario: Mapped[int] = mapped_column(Integer, default=1, server_default="1")
    # The phase's adaptive evaluation when the run was made (None: fixed): each round adds
    # episode_round episodes per reactive scenario; episodes_per_scenario counts those so far.
    adaptive_target: Mapped[float | None] = mapped_column(Float)
    max_episodes: Mapped[int | None] = mapped_column(Integer)
    episode_round: Mapped[int] = mapped_column(Integer, default=1, server_default="1")
    scoring_profile: Mapped[str] = mapped_column(String(64))
    scoring_version: Mapped[str] = mapped_column(String(32), default="")
    worker: Mapped[str] = mapped_column(String(255), default="")
    lease_expires_at: Mapped[datetime | None]
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
    started_at: Mapped[datetime | None]
    finished_at: Mapped[datetime | None]
    error: Mapped[str] = mapped_column(Text, default="")
    # The trained output this run evaluates (offline submissions); None for freestyle.
    training_id: Mapped[int | None] = mapped_column(ForeignKey("training_jobs.id"))
    # The agent's CPU limits [s] it is evaluated under, fixed when it is made (the phase's, else
    # the settings'). None: a run made before they were recorded (the settings' apply).
    step_cpu_s: Mapped[float | None] = mapped_column(Float)
    episode_cpu_s: Mapped[float | None] = mapped_column(Float)
    evaluation_cpu_s: Mapped[float | None] = mapped_column(Float)

    submission: Mapped[Submission] = relationship(back_populates="runs")
    training: Mapped[TrainingJob | None] = relationship()
    results: Mapped[list[ScenarioResult]] = relationship(back_populates="run")
    score: Mapped[Score | None] = relationship(back_populates="run")


class ScenarioResult(LeasedJob, Base):
    """The outcome of one episode of one scenario in one run. Unique per (run, scenario,
    episode): a redelivered task finds the row already there and cannot count it twice. A job
    of the engine while it runs: each claim of the episode has its own lease, so the other
    episodes of the run renewing theirs does not keep a dead worker's from being taken over."""

    __tablename__ = "scenario_results"
    __table_args__ = (UniqueConstraint("run_id", "scenario_id", "episode"),)

    id: Mapped[int] = mapped_column(primary_key=True)
    run_id: Mapped[int] = mapped_column(ForeignKey("evaluation_runs.id"))
    scenario_id: Mapped[str] = mapped_column(String(128))
    episode: Mapped[int] = mapped_column(Integer, default=0, server_default="0")
    family: Mapped[str] = mapped_column(String(64))
    # The core's vocabulary (arena.outcome); only `done` is charged to the submission.
    status: Mapped[ScenarioStatus] = mapped_column(
        Enum(ScenarioStatus, native_enum=False, length=32, validate_strings=True)
    )
    reason: Mapped[str] = mapped_column(String(64), default="")
    steps: Mapped[int] = mapped_column(Integer, default=0)
    # The episode record in the artifact store; None when no agent drove a step.
    record_key: Mapped[str | None] = mapped_column(String(512))
    log_tail: Mapped[str] = mapped_column(Text, default="")
    detail: Mapped[dict[str, Any]] = mapped_column(default=dict)
    # The CPU time the agent's acts used [s]: what the run's evaluation budget counts. None while
    # it runs, and for episodes stored before it was measured.
    agent_cpu_s: Mapped[float | None] = mapped_column(Float)
    created_at: Mapped[datetime] = mapped_column(default=utcnow)

    run: Mapped[EvaluationRun] = relationship(back_populates="results")

    @hybrid_property
    def under_way(self) -> bool:
        return self.status == ScenarioStatus.running


class Score(Base):
    """The four metrics of a run (all errors: smaller is better) and their per-family values."""

    __tablename__ = "scores"

    id: Mapped[int] = mapped_column(primary_key=True)
    run_id: Mapped[int] = mapped_column(ForeignKey("evaluation_runs.id"), unique=True)
    completion: Mapped[float] = mapped_column(Float)
    time: Mapped[float] = mapped_column(Float)
    # NULL when no agent drove a step: nothing measured (0 would be the best value).
    humanness: Mapped[float | None] = mapped_column(Float)
    rules: Mapped[float | None] = mapped_column(Float)
    # The 95% bootstrap interval of completion (evaluator/scoring/interval.py); NULL for scores
    # written before intervals existed.
    completion_low: Mapped[float | None] = mapped_column(Float)
    completion_high: Mapped[float | None] = mapped_column(Float)
    families: Mapped[dict[str, Any]] = mapped_column(default=dict)
    # Per scenario, each episode's values (evaluator/scoring/significance.py MetricSamples): what
    # the leaderboard's rank ranges resample. NULL for scores written before they were kept.
    # Deferred: only the leaderboard reads it, and only for scores it has not resampled yet.
    samples: Mapped[dict[str, Any] | None] = mapped_column(deferred=True)
    # The reproducibility manifest (evaluator/provenance.py Manifest): what the score depends on.
    # NULL for scores written before manifests existed. Deferred: the leaderboard never reads it.
    manifest: Mapped[dict[str, Any] | None] = mapped_column(deferred=True)
    profile: Mapped[str] = mapped_column(String(64))
    profile_version: Mapped[str] = mapped_column(String(32), default="")
    computed_at: Mapped[datetime] = mapped_column(default=utcnow)

    run: Mapped[EvaluationRun] = relationship(back_populates="score")


class SeedSetScore(Base):
    """The score of a seed set of several seeds (evaluator/scoring/seeds.py): the four metrics
    and per-family values as means over the seeds, completion's interval over seeds x scenarios,
    and the seeds' spread. Each seed's own run keeps its :class:`Score`."""

    __tablename__ = "seed_set_scores"
    __table_args__ = (UniqueConstraint("submission_id", "seed_set"),)

    id: Mapped[int] = mapped_column(primary_key=True)
    submission_id: Mapped[int] = mapped_column(ForeignKey("submissions.id"), index=True)
    seed_set: Mapped[int] = mapped_column(Integer)
    # The latest attempt among the seeds' runs: orders it against the submission's other scores.
    attempt: Mapped[int] = mapped_column(Integer)
    episodes_per_scenario: Mapped[int] = mapped_column(Integer, default=1)
    completion: Mapped[float] = mapped_column(Float)
    time: Mapped[float] = mapped_column(Float)
    humanness: Mapped[float | None] = mapped_column(Float)
    rules: Mapped[float | None] = mapped_column(Float)
    completion_low: Mapped[float | None] = mapped_column(Float)
    completion_high: Mapped[float | None] = mapped_column(Float)
    # The seeds' own completion errors: lowest, highest, standard deviation.
    seed_completion_min: Mapped[float] = mapped_column(Float)
    seed_completion_max: Mapped[float] = mapped_column(Float)
    seed_completion_std: Mapped[float] = mapped_column(Float)
    # Per seed: {"seed", "training_id", "run_id", and the four metrics}, in seed order.
    per_seed: Mapped[list[dict[str, Any]]] = mapped_column(JSON, default=list)
    families: Mapped[dict[str, Any]] = mapped_column(default=dict)
    # The seeds' samples pooled (evaluator/scoring/seeds.py pooled_samples): what the
    # leaderboard's rank ranges resample. Deferred like Score.samples.
    samples: Mapped[dict[str, Any] | None] = mapped_column(deferred=True)
    profile: Mapped[str] = mapped_column(String(64))
    profile_version: Mapped[str] = mapped_column(String(32), default="")
    computed_at: Mapped[datetime] = mapped_column(default=utcnow)

    submission: Mapped[Submission] = relationship(back_populates="seed_set_scores")


class LeaderboardGeneration(Base):
    """One counter, bumped whenever a change can reorder the leaderboard (a score written or
    replaced, a disqualification). API processes compare it to drop their cached leaderboard."""

    __tablename__ = "leaderboard_generation"

    id: Mapped[int] = mapped_column(primary_key=True)
    value: Mapped[int] = mapped_column(BigInteger, default=0)


class Artifact(Base):
    """A stored file of the database artifact store (``ARENA_ARTIFACT_STORE=database``)."""

    __tablename__ = "artifacts"

    key: Mapped[str] = mapped_column(String(512), primary_key=True)
    sha256: Mapped[str] = mapped_column(String(64))
    size: Mapped[int] = mapped_column(BigInteger)
    data: Mapped[bytes] = mapped_column(LargeBinary)
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
