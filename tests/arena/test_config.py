from __future__ import annotations

from pathlib import Path

import pydantic
import pytest

from arena.config import SandboxKind, SandboxSettings, Settings, StorageSettings
from tests.settings import env_only, with_fields

# Every environment variable the deployment documents, and where it lands: the names did not
# change when the settings were grouped (docs/, docker-compose.yml and .env files still hold).
VARIABLES = {
    "ARENA_DATA_DIR": ("storage", "data_dir", "/srv/arena", Path("/srv/arena")),
    "ARENA_DATABASE_URL": ("storage", "database_url", "postgresql://db/a", "postgresql://db/a"),
    "ARENA_BROKER_URL": ("storage", "broker_url", "redis://r:6379/0", "redis://r:6379/0"),
    "ARENA_DATABASE_PASSWORD": ("storage", "database_password", "pw1", "pw1"),
    "ARENA_BROKER_PASSWORD": ("storage", "broker_password", "pw2", "pw2"),
    "ARENA_ARTIFACT_STORE": ("storage", "artifact_store", "database", "database"),
    "ARENA_DEVELOPMENT_SEED": ("suites", "development_seed", "7", 7),
    "ARENA_HIDDEN_SEED": ("suites", "hidden_seed", "11", 11),
    "ARENA_HIDDEN_SUITE_DIR": ("suites", "hidden_suite_dir", "/h", Path("/h")),
    "ARENA_PUBLIC_SUITE_DIR": ("suites", "public_suite_dir", "/p", Path("/p")),
    "ARENA_NATURALISTIC_DIR": ("suites", "naturalistic_dir", "/n", Path("/n")),
    "ARENA_SANDBOX": ("sandbox", "kind", "bubblewrap", SandboxKind.bubblewrap),
    "ARENA_AGENT_IMAGE": ("sandbox", "agent_image", "img:1", "img:1"),
    "ARENA_BUILDER_IMAGE": ("sandbox", "builder_image", "img:2", "img:2"),
    "ARENA_DOCKER_RUNTIME": ("sandbox", "docker_runtime", "runsc", "runsc"),
    "ARENA_SANDBOX_SHARED_DIR": ("sandbox", "sandbox_shared_dir", "/s", Path("/s")),
    "ARENA_DEBIAN_MIRROR": (
        "sandbox",
        "debian_mirror",
        "http://127.0.0.1:9/d",
        "http://127.0.0.1:9/d",
    ),
    "ARENA_INIT_CPU_S": ("sandbox", "init_cpu_s", "6", 6.0),
    "ARENA_INIT_TIMEOUT_S": ("sandbox", "init_timeout_s", "5", 5.0),
    "ARENA_RUNTIME_START_TIMEOUT_S": ("sandbox", "runtime_start_timeout_s", "8", 8.0),
    "ARENA_STEP_CPU_S": ("sandbox", "step_cpu_s", "2", 2.0),
    "ARENA_STEP_TIMEOUT_S": ("sandbox", "step_timeout_s", "3", 3.0),
    "ARENA_EPISODE_CPU_S": ("sandbox", "episode_cpu_s", "4", 4.0),
    "ARENA_EPISODE_TIMEOUT_S": ("sandbox", "episode_timeout_s", "5", 5.0),
    "ARENA_EVALUATION_CPU_S": ("sandbox", "evaluation_cpu_s", "7", 7.0),
    "ARENA_AGENT_MEMORY_BYTES": ("sandbox", "agent_memory_bytes", "1000", 1000),
    "ARENA_AGENT_CPUS": ("sandbox", "agent_cpus", "2", 2.0),
    "ARENA_AGENT_PIDS": ("sandbox", "agent_pids", "9", 9),
    "ARENA_AGENT_TMP_BYTES": ("sandbox", "agent_tmp_bytes", "10", 10),
    "ARENA_AGENT_LOG_TAIL_BYTES": ("sandbox", "agent_log_tail_bytes", "11", 11),
    "ARENA_AGENT_PYTHON_VERSION": ("sandbox", "agent_python_version", "3.12", "3.12"),
    "ARENA_AGENT_GLIBC_VERSION": ("sandbox", "agent_glibc_version", "2.40", "2.40"),
    "ARENA_WARM_AGENTS": ("sandbox", "warm_agents", "false", False),
    "ARENA_WARM_AGENT_IDLE_S": ("sandbox", "warm_agent_idle_s", "12", 12.0),
    "ARENA_PIN_JOBS": ("sandbox", "pin_jobs", "false", False),
    "ARENA_MAX_ZIP_BYTES": ("intake", "max_zip_bytes", "13", 13),
    "ARENA_MAX_UNZIPPED_BYTES": ("intake", "max_unzipped_bytes", "14", 14),
    "ARENA_MAX_ZIP_ENTRIES": ("intake", "max_zip_entries", "15", 15),
    "ARENA_MAX_COMPRESSION_RATIO": ("intake", "max_compression_ratio", "16", 16.0),
    "ARENA_MAX_DEPS_DOWNLOAD_BYTES": ("intake", "max_deps_download_bytes", "17", 17),
    "ARENA_MAX_DEPS_BYTES": ("intake", "max_deps_bytes", "18", 18),
    "ARENA_MAX_DEPS_FILES": ("intake", "max_deps_files", "19", 19),
    "ARENA_PACKAGE_INDEX": ("intake", "package_index", '["/srv/wheels"]', ["/srv/wheels"]),
    "ARENA_MAX_WHEEL_BYTES": ("intake", "max_wheel_bytes", "17", 17),
    "ARENA_MAX_TEAM_DEPS_BYTES": ("intake", "max_team_deps_bytes", "17", 17),
    "ARENA_RESOLVER_TIMEOUT_S": ("intake", "resolver_timeout_s", "17", 17.0),
    "ARENA_RESOLVER_MEMORY_BYTES": ("intake", "resolver_memory_bytes", "17", 17),
    "ARENA_INTAKE_MEMORY_BYTES": ("intake", "intake_memory_bytes", "20", 20),
    "ARENA_INTAKE_TIMEOUT_S": ("intake", "intake_timeout_s", "21", 21.0),
    "ARENA_VALIDATION_BUDGET_S": ("intake", "validation_budget_s", "900", 900.0),
    "ARENA_VALIDATION_SLICE_S": ("intake", "validation_slice_s", "12.5", 12.5),
    "ARENA_TRAIN_DATASET_DIR": ("training", "train_dataset_dir", "/d", Path("/d")),
    "ARENA_TRAIN_TIMEOUT_S": ("training", "train_timeout_s", "22", 22.0),
    "ARENA_TRAIN_OUTPUT_BYTES": ("training", "train_output_bytes", "23", 23),
    "ARENA_TRAIN_OUTPUT_FILES": ("training", "train_output_files", "24", 24),
    "ARENA_TRAIN_OUTPUT_DEPTH": ("training", "train_output_depth", "25", 25),
    "ARENA_TRAIN_GPU": ("training", "train_gpu", "true", True),
    "ARENA_TRAIN_CHECKPOINT_INTERVAL_S": ("training", "train_checkpoint_interval_s", "0", 0.0),
    "ARENA_TRAIN_CHECKPOINT_BYTES": ("training", "train_checkpoint_bytes", "26", 26),
    "ARENA_EPISODES_PER_SCENARIO": ("evaluation", "episodes_per_scenario", "3", 3),
    "ARENA_SCORING_PROFILE": ("evaluation", "scoring_profile", "other", "other"),
    "ARENA_JOBS": ("evaluation", "jobs", "4", 4),
    "ARENA_DAILY_QUOTA": ("service", "daily_quota", "27", 27),
    "ARENA_ADMIN_TOKEN": ("service", "admin_token", "t0k", "t0k"),
    "ARENA_LEASE_SECONDS": ("service", "lease_seconds", "28", 28),
    "ARENA_OVERDUE_AFTER_S": ("service", "overdue_after_s", "29", 29.0),
    "ARENA_BROKER_KEY_PREFIX": ("service", "broker_key_prefix", "x:", "x:"),
    "ARENA_REAPER_INTERVAL_S": ("service", "reaper_interval_s", "30", 30.0),
    "ARENA_PUBLIC_BASE_URL": ("service", "public_base_url", "https://a", "https://a"),
    "ARENA_HTTP_HEADER_TIMEOUT_S": ("service", "http_header_timeout_s", "31", 31.0),
    "ARENA_HTTP_KEEP_ALIVE_S": ("service", "http_keep_alive_s", "32", 32.0),
}


def test_every_variable_reaches_its_field(monkeypatch):
    for variable, (_, _, text, _) in VARIABLES.items():
        monkeypatch.setenv(variable, text)
    settings = Settings.load(env_file=None)
    for variable, (group, name, _, value) in VARIABLES.items():
        assert getattr(getattr(settings, group), name) == value, variable


# The secrets' files (a deployment's way: tests/arena/test_secret_settings.py reads them).
SECRET_FILE_VARIABLES = {
    "ARENA_DATABASE_URL_FILE": ("storage", "database_url_file"),
    "ARENA_DATABASE_PASSWORD_FILE": ("storage", "database_password_file"),
    "ARENA_BROKER_URL_FILE": ("storage", "broker_url_file"),
    "ARENA_BROKER_PASSWORD_FILE": ("storage", "broker_password_file"),
    "ARENA_HIDDEN_SEED_FILE": ("suites", "hidden_seed_file"),
    "ARENA_ADMIN_TOKEN_FILE": ("service", "admin_token_file"),
}


def test_every_field_has_a_listed_variable():
    # A field added to a group without its variable here is a name nobody checked.
    named = {
        (group, name): variable
        for group, field in Settings.model_fields.items()
        for name, variable in field.annotation.env_names().items()
    }
    listed = {(g, n): v for v, (g, n, _, _) in VARIABLES.items()}
    assert named == listed | {place: v for v, place in SECRET_FILE_VARIABLES.items()}


def test_the_env_file_is_read_by_every_group(tmp_path, monkeypatch):
    for variable in VARIABLES:
        monkeypatch.delenv(variable, raising=False)
    env_file = tmp_path / ".env"
    env_file.write_text("ARENA_SANDBOX=process\nARENA_JOBS=5\nARENA_DATA_DIR=/e\nOTHER=1\n")
    settings = Settings.load(env_file=env_file)
    assert settings.sandbox.kind is SandboxKind.process
    assert settings.evaluation.jobs == 5
    assert settings.storage.data_dir == Path("/e")


def test_flat_names_are_refused():
    with pytest.raises(pydantic.ValidationError, match="step_cpu_s"):
        Settings(step_cpu_s=2.0)
    with pytest.raises(TypeError, match="step_cpu_s"):
        StorageSettings(step_cpu_s=2.0)
    with pytest.raises(TypeError, match="no field step_cpu_s"):
        with_fields(env_only(), storage={"step_cpu_s": 2.0})


def test_groups_are_typed_and_frozen():
    settings = env_only(sandbox={"kind": "docker", "step_cpu_s": "2.5"})
    assert settings.sandbox.kind is SandboxKind.docker
    assert settings.sandbox.step_cpu_s == 2.5
    with pytest.raises(pydantic.ValidationError):
        settings.sandbox.step_cpu_s = 3.0
    with pytest.raises(pydantic.ValidationError):
        settings.sandbox = SandboxSettings()
    with pytest.raises(pydantic.ValidationError):
        SandboxSettings(kind="chroot")
    with pytest.raises(pydantic.ValidationError):
        with_fields(settings, evaluation={"jobs": 0})


def test_with_fields_changes_only_what_it_names():
    base = env_only(sandbox={"step_cpu_s": 2.0, "init_timeout_s": 7.0})
    changed = with_fields(base, sandbox={"step_cpu_s": 3.0})
    assert (changed.sandbox.step_cpu_s, changed.sandbox.init_timeout_s) == (3.0, 7.0)
    assert base.sandbox.step_cpu_s == 2.0
    assert changed.storage is base.storage


def test_load_keeps_the_groups_it_is_given(monkeypatch):
    monkeypatch.setenv("ARENA_DATA_DIR", "/from-env")
    given = StorageSettings(_env_file=None, data_dir="/given")
    settings = Settings.load(env_file=None, storage=given)
    assert settings.storage is given
    assert Settings.load(env_file=None).storage.data_dir == Path("/from-env")
