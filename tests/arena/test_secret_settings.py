"""The secrets are read from files (a deployment) or plain variables (local use), never echoed,
and withdrawn from the environment once read; no child is handed one."""

from __future__ import annotations

import os

import pydantic
import pytest

from arena.child_env import SecretPassedOn, child_environment
from arena.config import Settings, get_settings, url_with_password
from tests.settings import env_only


def secret_file(tmp_path, name: str, text: str):
    path = tmp_path / name
    path.write_text(text)
    path.chmod(0o400)
    return path


def test_each_secret_is_read_from_its_file(tmp_path, monkeypatch):
    monkeypatch.setenv("ARENA_ADMIN_TOKEN_FILE", str(secret_file(tmp_path, "a", "t0ken\n")))
    monkeypatch.setenv("ARENA_HIDDEN_SEED_FILE", str(secret_file(tmp_path, "h", "a long phrase\n")))
    monkeypatch.setenv("ARENA_DATABASE_URL", "postgresql+psycopg://arena@db:5432/arena")
    monkeypatch.setenv("ARENA_DATABASE_PASSWORD_FILE", str(secret_file(tmp_path, "d", "p@ss/w:d")))
    monkeypatch.setenv("ARENA_BROKER_URL_FILE", str(secret_file(tmp_path, "b", "redis://:x@r/0\n")))
    settings = env_only()
    assert settings.service.admin_token == "t0ken"
    assert (
        settings.suites.hidden_seed
        == env_only(suites={"hidden_seed": "a long phrase"}).suites.hidden_seed
    )
    # The password joins the password-free URL, percent-encoded as both clients decode it.
    assert settings.storage.resolved_database_url == (
        "postgresql+psycopg://arena:p%40ss%2Fw%3Ad@db:5432/arena"
    )
    assert settings.storage.resolved_broker_url == "redis://:x@r/0"


def test_a_secret_given_twice_or_unreadable_is_named_never_shown(tmp_path, monkeypatch):
    monkeypatch.setenv("ARENA_ADMIN_TOKEN", "plain-value-1")
    monkeypatch.setenv("ARENA_ADMIN_TOKEN_FILE", str(secret_file(tmp_path, "a", "file-value-2")))
    with pytest.raises(pydantic.ValidationError) as both:
        env_only()
    assert "ARENA_ADMIN_TOKEN_FILE" in str(both.value)
    assert "value-1" not in str(both.value) and "value-2" not in str(both.value)
    monkeypatch.delenv("ARENA_ADMIN_TOKEN")
    monkeypatch.setenv("ARENA_ADMIN_TOKEN_FILE", str(tmp_path / "missing"))
    with pytest.raises(pydantic.ValidationError, match="ARENA_ADMIN_TOKEN_FILE: cannot read"):
        env_only()


def test_a_password_needs_a_url_without_one():
    with pytest.raises(ValueError, match="already holds a password"):
        url_with_password("redis://:a@r:6379/0", "b")
    with pytest.raises(pydantic.ValidationError, match="without a URL"):
        env_only(storage={"database_password": "pw"})


def test_the_plain_variables_are_withdrawn_once_read(monkeypatch):
    monkeypatch.setenv("ARENA_ADMIN_TOKEN", "local-token")
    monkeypatch.setenv("ARENA_JOBS", "3")
    get_settings.cache_clear()
    try:
        settings = get_settings()
        assert settings.service.admin_token == "local-token"
        assert "ARENA_ADMIN_TOKEN" not in os.environ
        assert os.environ["ARENA_JOBS"] == "3"  # only the secrets
    finally:
        get_settings.cache_clear()


def test_no_child_environment_holds_a_secret(monkeypatch):
    for name in Settings.secret_env_names():
        monkeypatch.setenv(name, "s3cret")
    monkeypatch.setenv("ARENA_JOBS", "3")
    monkeypatch.setenv("PIP_INDEX_URL", "http://127.0.0.1:9/simple")
    env = child_environment({"A": "1"}, inherit=["ARENA_*", "PIP_*", "HOME"])
    assert "s3cret" not in env.values()
    assert env["ARENA_JOBS"] == "3" and env["A"] == "1" and "PIP_INDEX_URL" in env
    # Nothing is inherited unless named.
    assert set(child_environment()) == {"PATH"}
    for name in Settings.secret_env_names():
        with pytest.raises(SecretPassedOn, match=name):
            child_environment(inherit=[name])
        with pytest.raises(SecretPassedOn, match=name):
            child_environment({name: "x"})
