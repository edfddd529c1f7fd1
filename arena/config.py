"""The settings of Driving Arena, grouped by concern.

Every tunable (paths, limits, service URLs, sandbox choice) is read here from the environment
(``ARENA_<FIELD>``; the sandbox's kind is ``ARENA_SANDBOX``) or an ``.env`` file, validated
once, and handed out by :func:`get_settings`. Only entry points (command lines, the service's
dependencies and tasks) call it; each layer below takes the group it needs as a parameter.
No other module reads ``os.environ`` for configuration.

The secrets (the admin token, the database's and the broker's credentials, the hidden seed) are
read from files in a deployment (``ARENA_<FIELD>_FILE``: compose ``secrets:``, mode 0400), so
that no process holds them in its environment, where every child would inherit them. The plain
variables still work for local use; :func:`get_settings` withdraws them from this process's
environment once read, and :func:`arena.child_env.child_environment` never passes one on.
"""

from __future__ import annotations

import os
from enum import StrEnum
from functools import lru_cache
from pathlib import Path
from typing import Annotated, Any, ClassVar
from urllib.parse import quote

from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, model_validator
from pydantic_settings import BaseSettings, SettingsConfigDict

from arena.cpu_limits import CpuLimits
from arena.seeds import parse_seed


class SandboxKind(StrEnum):
    docker = "docker"
    bubblewrap = "bubblewrap"
    # Unsandboxed subprocess with rlimits only: participants' local runs; the service refuses it.
    process = "process"
    auto = "auto"


class ArtifactBackend(StrEnum):
    # The data folder: one machine (or a shared volume).
    folder = "folder"
    # The database: workers on several machines share nothing but it and the broker.
    database = "database"


def _seed_or_none(value: object) -> object:
    if value is None or value == "":
        return None
    return parse_seed(value) if isinstance(value, str | int) else value


# A secret file holds one value, a line at most; more is a wrong path (a folder's archive, a log).
SECRET_FILE_MAX_BYTES = 64 * 1024


def read_secret_file(path: Path, variable: str) -> str:
    """The secret in ``path`` (named by ``variable``), its final newline dropped."""
    try:
        with open(path, "rb") as handle:
            data = handle.read(SECRET_FILE_MAX_BYTES + 1)
    except OSError as error:
        raise ValueError(f"{variable}: cannot read {path}: {error.strerror}") from None
    if len(data) > SECRET_FILE_MAX_BYTES:
        raise ValueError(f"{variable}: {path} is larger than a secret ({len(data)} bytes)")
    value = data.decode("utf-8", errors="strict").rstrip("\r\n")
    if not value:
        raise ValueError(f"{variable}: {path} is empty")
    return value


def url_with_password(url: str, password: str) -> str:
    """``url`` with ``password`` (percent-encoded) as its user's password: a password-free URL
    in the environment, the password from a secret file."""
    scheme, separator, rest = url.partition("://")
    netloc, slash, path = rest.partition("/")
    userinfo, _, host = netloc.rpartition("@")
    if not separator or not host:
        raise ValueError(f"{url!r} names no host to log in to")
    if ":" in userinfo:
        raise ValueError("the URL already holds a password: give it in one place")
    return f"{scheme}://{userinfo}:{quote(password, safe='')}@{host}{slash}{path}"


class SettingsGroup(BaseSettings):
    """One concern's settings, read from ``ARENA_<FIELD>`` in the environment or ``.env``.

    Each group reads only its own names; the others' in the same ``.env`` are not its business
    (hence extra="ignore"), but a keyword that is none of its fields is a mistake in the caller
    and fails instead of being dropped.
    """

    model_config = SettingsConfigDict(
        env_prefix="ARENA_",
        env_file=".env",
        extra="ignore",
        frozen=True,
        populate_by_name=True,
        # A refused value may be a secret: the error names the variable, never echoes its value.
        hide_input_in_errors=True,
    )
    # The fields holding a secret: each also read from the file its `<field>_file` names.
    secret_fields: ClassVar[tuple[str, ...]] = ()

    def __init__(self, **values: Any) -> None:
        fields = type(self).model_fields
        known = set(fields) | {f.validation_alias for f in fields.values() if f.validation_alias}
        unknown = sorted(k for k in values if not k.startswith("_") and k not in known)
        if unknown:
            raise TypeError(f"{type(self).__name__} has no field {', '.join(unknown)}")
        super().__init__(**values)

    @classmethod
    def env_names(cls) -> dict[str, str]:
        """Each field's environment variable."""
        return {
            name: str(field.validation_alias or f"ARENA_{name}").upper()
            for name, field in cls.model_fields.items()
        }

    @classmethod
    def secret_env_names(cls) -> frozenset[str]:
        """The variables that hold a secret itself (not the ones naming its file)."""
        names = cls.env_names()
        return frozenset(names[field] for field in cls.secret_fields)

    @model_validator(mode="before")
    @classmethod
    def _read_secret_files(cls, data: Any) -> Any:
        if not isinstance(data, dict):
            return data
        names = cls.env_names()
        for field in cls.secret_fields:
            path = data.get(f"{field}_file")
            if path is None or path == "":
                continue
            variable = names[f"{field}_file"]
            value = read_secret_file(Path(path), variable)
            given = data.get(field)
            # Settings copied with their values (tests' with_fields) carry both, equal.
            if given not in (None, "") and str(given) != value:
                raise ValueError(
                    f"both {names[field]} and {variable} are set: keep one (the file, in a "
                    "deployment)"
                )
            data = {**data, field: value}
        return data


class StorageSettings(SettingsGroup):
    """Where everything the service writes lives, and its backends."""

    # The database, uploads, results, scenario builds.
    data_dir: Path = Path(".arena")
    # Service backends. Empty: the embedded default under data_dir (SQLite + SQLAlchemy broker).
    # Secrets when they hold a password: in a deployment, a password-free URL here and the
    # password in a file (`*_password_file`), or the whole URL in a file (`*_url_file`).
    database_url: str = ""
    database_url_file: Path | None = None
    database_password: str = ""
    database_password_file: Path | None = None
    broker_url: str = ""
    broker_url_file: Path | None = None
    broker_password: str = ""
    broker_password_file: Path | None = None
    # Where uploads and episode records live between processes (server/core/artifacts.py).
    artifact_store: ArtifactBackend = ArtifactBackend.folder

    @property
    def resolved_data_dir(self) -> Path:
        return self.data_dir.expanduser().resolve()

    secret_fields = ("database_url", "database_password", "broker_url", "broker_password")

    @model_validator(mode="after")
    def _passwords_need_urls(self) -> StorageSettings:
        for kind in ("database", "broker"):
            url, password = getattr(self, f"{kind}_url"), getattr(self, f"{kind}_password")
            if password:
                if not url:
                    raise ValueError(f"ARENA_{kind.upper()}_PASSWORD is set without a URL")
                url_with_password(url, password)  # a URL it cannot join fails now, not later
        return self

    @property
    def resolved_database_url(self) -> str:
        if not self.database_url:
            return f"sqlite:///{self.resolved_data_dir / 'arena.db'}"
        if self.database_password:
            return url_with_password(self.database_url, self.database_password)
        return self.database_url

    @property
    def resolved_broker_url(self) -> str:
        if not self.broker_url:
            return f"sqla+sqlite:///{self.resolved_data_dir / 'broker.db'}"
        if self.broker_password:
            return url_with_password(self.broker_url, self.broker_password)
        return self.broker_url


class SuiteSettings(SettingsGroup):
    """The scenario suites: their seeds and folders."""

    development_seed: int = 20221128
    # The organisers' secret seed for the hidden suite; never committed, only set in deployment
    # (a file, read by the suite builder alone). A number or a passphrase (arena/seeds.py: how
    # to pick a strong one).
    hidden_seed: Annotated[int | None, BeforeValidator(_seed_or_none)] = None
    hidden_seed_file: Path | None = None
    hidden_suite_dir: Path | None = None
    public_suite_dir: Path | None = None
    # The naturalistic scenes (CommonRoad NGSIM); None: the shipped
    # scenarios/data/naturalistic/commonroad-ngsim.
    naturalistic_dir: Path | None = None

    secret_fields = ("hidden_seed",)


class SandboxSettings(SettingsGroup):
    """Where a participant's code runs, and its limits."""

    # ARENA_SANDBOX, as before the settings were grouped.
    kind: SandboxKind = Field(default=SandboxKind.auto, validation_alias="ARENA_SANDBOX")
    agent_image: str = "driving-arena-agent:latest"
    # The image the resolver builds sdists into wheels in under Docker: the agent's with a C/C++
    # toolchain and Python's headers, so the image that runs policies has no compiler.
    builder_image: str = "driving-arena-builder:latest"
    # The OCI runtime the Docker daemon runs agents with: empty, its default (runc); `runsc`,
    # gVisor's, where the daemon has it registered (docs/sandbox.md, "A stronger tier").
    docker_runtime: str = ""
    # A folder at the same path for this process and for the Docker daemon, when the worker
    # runs in a container and starts its agents beside it (docker-compose.yml): the agent
    # runtime is copied there and the protocol sockets made there, since the daemon binds host
    # paths. None: the worker runs on the daemon's host (the package and the temporary folder).
    sandbox_shared_dir: Path | None = None
    # Debian mirror the offline agent image is bootstrapped from; empty: the host's apt sources.
    debian_mirror: str = ""
    # Loading the policy (importing policy.py, Policy()) and each reset, counted from the
    # runtime's hello (docs/protocol.md, "Time limits"): the agent's own CPU time, as for an act,
    # so that a busy worker (two evaluations, a slow disk) charges the team nothing; the wall
    # clock only as the backstop for an agent that waits or sleeps, five times the CPU limit: a
    # legal start-up near its 60 s of CPU then still finishes with the agent given a fifth of a
    # CPU. Where no CPU meter exists, init_cpu_s applies to the wall clock. Both are charged
    # init_timeout.
    init_cpu_s: float = 60.0
    init_timeout_s: float = 300.0
    # Our runtime's own start, until its hello, and a warm zygote's: wall time, and a failure
    # there is ours (sandbox_error; a silent zygote's agents start cold). Nothing of the team's
    # runs yet, so no backstop of theirs applies.
    runtime_start_timeout_s: float = 60.0
    # An act's limits (docs/protocol.md, "Time limits"): the agent's own CPU time, read from the
    # host, so that a busy worker changes no score; the wall clock only as a generous backstop
    # (an agent that sleeps or waits uses no CPU). Where no CPU meter exists, step_cpu_s
    # applies to the wall clock.
    step_cpu_s: float = 1.0
    step_timeout_s: float = 30.0
    # The agent CPU time one episode (every act together) may use; the episode's wall limit
    # (simulator included) is episode_timeout_s.
    episode_cpu_s: float = 600.0
    episode_timeout_s: float = 600.0
    # The agent CPU time one evaluation (every episode together) may use, the 2022 competition's
    # figure: once passed, the remaining episodes are not run and the submission fails. A phase
    # may override it and the two above (`arena admin phases set`).
    evaluation_cpu_s: float = Field(default=64_800.0, gt=0)
    agent_memory_bytes: int = 2 * 1024**3
    agent_cpus: float = 1.0
    agent_pids: int = 64
    agent_tmp_bytes: int = 64 * 1024**2
    agent_log_tail_bytes: int = 64 * 1024
    # The sandbox's interpreter (the agent image's and bubblewrap's Debian bookworm python3):
    # a submission's requirements are resolved to wheels for it, not for the host's Python.
    agent_python_version: str = "3.11"
    agent_glibc_version: str = "2.36"
    # Warm agents (docs/protocol.md): one sandbox per submission and evaluating process forks a
    # fresh agent for each episode; off: a new sandbox per episode. Idle ones close after this.
    warm_agents: bool = True
    warm_agent_idle_s: float = 120.0
    # Each evaluation job's simulator and agent on the same CPU (evaluator/sandbox/placement.py,
    # docs/performance.md "The round trip"): every step is a strict hand-off between the two, and
    # across CPUs each hand-off wakes an idle core (about 50 us on a virtual machine, twice a
    # step); on one CPU it is a context switch. Job i gets CPU i of this process's allowed set
    # (round robin when jobs exceed CPUs; ceil(agent_cpus) CPUs a job when the agent may use
    # more than one, none when that is all of them), or the first CPU no other job on the machine
    # holds (a service worker's pool process is a job; none free: not pinned). The agent's quota
    # (agent_cpus) and its CPU time limits are unchanged: they count its own CPU time, and the
    # simulator waits while the agent computes. On by default, from measurements side by side
    # (docs/performance.md "One CPU a job"): on a quiet 2-core VM a hand-off took 17 us pinned
    # against 64-80 us, and on a busy one the round trip was the same either way.
    # ARENA_PIN_JOBS=false leaves placement to the scheduler: for a host whose CPUs other
    # processes keep busy, where a pinned job cannot move.
    pin_jobs: bool = True

    @property
    def cpu_limits(self) -> CpuLimits:
        return CpuLimits(self.step_cpu_s, self.episode_cpu_s, self.evaluation_cpu_s)


class IntakeSettings(SettingsGroup):
    """The checks an upload passes before it is accepted."""

    max_zip_bytes: int = 100 * 1024**2
    max_unzipped_bytes: int = 500 * 1024**2
    max_zip_entries: int = 10_000
    max_compression_ratio: float = 200.0
    # Requirements (docs/submissions.md): one wheel (torch's CPU build is 183 MiB), the whole
    # stack downloaded, and the whole stack unpacked (bytes and files).
    max_wheel_bytes: int = 512 * 1024**2
    max_deps_download_bytes: int = 1536 * 1024**2
    max_deps_bytes: int = 4096 * 1024**2
    max_deps_files: int = 100_000
    # What one team's kept submissions may add to the shared wheel store, unpacked: the wheels
    # no other team's submissions use (a shared wheel is charged to no one).
    max_team_deps_bytes: int = 16 * 1024**3
    # Where requirements resolve from: index URLs (the first is pip's index, the rest extra
    # indexes) and wheel folders. Empty: the host's pip configuration (index-url,
    # extra-index-url, find-links; never its constraints). The resolver sandbox reaches these and
    # nothing else (docs/sandbox.md).
    package_index: list[str] = Field(default_factory=list)
    # The resolver sandbox (evaluator/sandbox/resolver.py): its wall time [s] and memory.
    resolver_timeout_s: float = 600.0
    resolver_memory_bytes: int = 2 * 1024**3
    # The validation of an upload (agent_runtime/intake.py in the sandbox): its memory, its wall
    # time [s] (per step: the zip, then the wheels). Disk: the unzipped and deps caps above.
    intake_memory_bytes: int = 1024**3
    intake_timeout_s: float = 300.0
    # Validation time [s] per team per UTC day: every validation (queued or rejected) is charged
    # the time it held a worker, and runs at most what is left; a team past it uploads again the
    # next day (docs/submissions.md).
    validation_budget_s: float = Field(default=1800.0, gt=0)
    # [s] A validation that has run this long yields its worker to a waiting validation of a team
    # that has used less validation time today (sent again, charged what it used): one team's
    # validations never hold up another's for longer.
    validation_slice_s: float = Field(default=30.0, gt=0)


class TrainingSettings(SettingsGroup):
    """Track 2 training (docs/dataset.md).

    `train.py` runs in the sandbox with the sandbox's memory and CPU limits, the dataset
    mounted read-only and a writable output folder.
    """

    # The dataset the service mounts (`arena dataset build --out DIR`); None: offline
    # submissions cannot be trained.
    train_dataset_dir: Path | None = None
    train_timeout_s: float = 1800.0
    train_output_bytes: int = 512 * 1024**2
    # And in entries (files, folders, links) and folder depth: 200,000 empty files passed the
    # byte cap, and walking them starved the lease heartbeat.
    train_output_files: int = 10_000
    train_output_depth: int = 16
    # Pass the host's GPUs to the training container (Docker only; needs the NVIDIA toolkit).
    train_gpu: bool = False
    # Snapshots of the output folder while train.py runs, in the artifact store: a training
    # re-sent after its worker died resumes from the last (docs/dataset.md). Taken every this
    # many seconds (0: never) when the folder changed and holds at most train_checkpoint_bytes.
    train_checkpoint_interval_s: float = Field(default=60.0, ge=0)
    train_checkpoint_bytes: int = 256 * 1024**2


class EvaluationSettings(SettingsGroup):
    """How a submission is evaluated and scored (a phase may override the first two)."""

    # Episodes of each reactive scenario, each with other traffic (arena/episodes.py); the
    # metrics average them. Evaluation takes about this many times as long.
    episodes_per_scenario: int = Field(default=1, ge=1)
    scoring_profile: str = "driving-smarts-2022"
    jobs: int = Field(default=2, ge=1)


class ServiceSettings(SettingsGroup):
    """The web service and its workers."""

    daily_quota: int = 5
    admin_token: str | None = None
    admin_token_file: Path | None = None
    # A claim's lease [s]: renewed every third of it; a dead worker's scenario is re-sent after
    # at most this plus one reaper interval.
    lease_seconds: int = 30
    # A submission queued, training or running longer than this [s] is listed by
    # `arena admin status` as overdue.
    overdue_after_s: float = Field(default=3600.0, gt=0)
    # Prefix on every broker key, so several deployments (or test sessions) can share one Redis.
    broker_key_prefix: str = ""
    # How often a worker looks for evaluations whose lease expired [s].
    reaper_interval_s: float = 10.0
    # Absolute URLs the service writes (none today: pages link relatively); never the Host header.
    public_base_url: str = ""
    # uvicorn: a client must send its request headers within this [s]; idle keep-alive ends after.
    http_header_timeout_s: float = 10.0
    http_keep_alive_s: float = 5.0

    secret_fields = ("admin_token",)


class Settings(BaseModel):
    """Every group; each layer is handed the group (or groups) it needs, not the whole.

    ``Settings()`` reads each group from the environment and ``.env``; a flat field
    (``Settings(step_cpu_s=2)``) is refused, it belongs to a group.
    """

    model_config = ConfigDict(frozen=True, extra="forbid")

    storage: StorageSettings = Field(default_factory=StorageSettings)
    suites: SuiteSettings = Field(default_factory=SuiteSettings)
    sandbox: SandboxSettings = Field(default_factory=SandboxSettings)
    intake: IntakeSettings = Field(default_factory=IntakeSettings)
    training: TrainingSettings = Field(default_factory=TrainingSettings)
    evaluation: EvaluationSettings = Field(default_factory=EvaluationSettings)
    service: ServiceSettings = Field(default_factory=ServiceSettings)

    @classmethod
    def load(cls, env_file: Path | str | None = ".env", **groups: SettingsGroup) -> Settings:
        """Every group from the environment and `env_file` (None: the environment only), but
        those given."""
        read = {
            name: field.annotation(_env_file=env_file)
            for name, field in cls.model_fields.items()
            if name not in groups
        }
        return cls(**read, **groups)

    @classmethod
    def secret_env_names(cls) -> frozenset[str]:
        """Every variable that holds a secret, whatever its group."""
        return frozenset().union(
            *(field.annotation.secret_env_names() for field in cls.model_fields.values())
        )

    @classmethod
    def env_names(cls) -> frozenset[str]:
        """Every settings variable, secrets and their files included."""
        return frozenset().union(
            *(field.annotation.env_names().values() for field in cls.model_fields.values())
        )


@lru_cache
def get_settings() -> Settings:
    """This process's settings. The secrets' plain variables are withdrawn from its environment
    once read, so that no child inherits them, even one started by a library (multiprocessing's
    fork server, a pool) rather than through :func:`arena.child_env.child_environment`."""
    settings = Settings()
    for name in Settings.secret_env_names():
        os.environ.pop(name, None)
    return settings
