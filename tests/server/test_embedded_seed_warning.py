"""`arena up` says the hidden suite comes from the public development seed at every start, not
only when it builds it: a demo folder must not drift into a competition unnoticed."""

from __future__ import annotations

from arena.config import Settings
from arena.suite import SuiteManifest, write_manifest
from arena.terminal import make_console
from scenarios.suites import seed_fingerprint
from server.embedded import _hidden_suite
from tests.settings import with_fields


def built_suite(folder, seed: int):
    folder.mkdir()
    write_manifest(
        folder, SuiteManifest(suite="hidden", scenarios=(), seed_fingerprint=seed_fingerprint(seed))
    )
    return folder


def test_a_development_seed_suite_is_warned_about_on_restart(tmp_path, capsys):
    settings = with_fields(
        Settings(),
        storage={"data_dir": tmp_path},
        suites={"hidden_suite_dir": built_suite(tmp_path / "dev", 20221128)},
    )
    assert _hidden_suite(make_console(), settings.suites, tmp_path, {}) == tmp_path / "dev"
    out = capsys.readouterr().out
    assert "the hidden suite is built from the PUBLIC DEVELOPMENT SEED 20221128" in out


def test_a_secret_seed_suite_is_not(tmp_path, capsys):
    settings = with_fields(
        Settings(),
        storage={"data_dir": tmp_path},
        suites={"hidden_suite_dir": built_suite(tmp_path / "s", 99)},
    )
    _hidden_suite(make_console(), settings.suites, tmp_path, {})
    assert "DEVELOPMENT SEED" not in capsys.readouterr().out
