"""Requirements are resolved from PyPI (the one network the tests may use)."""

from __future__ import annotations

from pathlib import Path

import pytest

from arena.config import Settings
from arena.errors import IntakeError
from submissions.intake import prepare_submission
from submissions.intake.dependencies import parse_requirements
from tests.settings import with_fields
from tests.submissions.zips import with_policy, write_zip

pytestmark = pytest.mark.slow


def test_requirements_install_from_wheels_and_are_cached(tmp_path: Path) -> None:
    settings = with_fields(Settings(), storage={"data_dir": tmp_path / "data"})
    upload = write_zip(tmp_path / "a.zip", with_policy(**{"requirements.txt": "six==1.16.0\n"}))
    first = prepare_submission(
        upload,
        tmp_path / "a",
        settings.intake,
        settings.sandbox,
        settings.storage.resolved_data_dir,
    )
    assert first.deps_dir is not None and (first.deps_dir / "six.py").is_file()
    second = prepare_submission(
        upload,
        tmp_path / "b",
        settings.intake,
        settings.sandbox,
        settings.storage.resolved_data_dir,
    )
    assert second.deps_dir == first.deps_dir


def test_a_requirement_without_a_wheel_is_rejected(tmp_path: Path) -> None:
    settings = with_fields(Settings(), storage={"data_dir": tmp_path / "data"})
    # PyYAML 5.1 (2019) published no wheels for CPython 3.11 on Linux: source only.
    upload = write_zip(tmp_path / "a.zip", with_policy(**{"requirements.txt": "PyYAML==5.1\n"}))
    with pytest.raises(IntakeError) as caught:
        prepare_submission(
            upload,
            tmp_path / "a",
            settings.intake,
            settings.sandbox,
            settings.storage.resolved_data_dir,
        )
    assert (caught.value.entry, caught.value.rule) == ("requirements.txt:1", "no-wheel")
    assert not (tmp_path / "a").exists()


def test_requirements_are_normalised_before_hashing() -> None:
    assert parse_requirements("numpy >= 1.24  # fast\n\n# comment\nsix==1.16.0\n") == [
        "numpy>=1.24",
        "six==1.16.0",
    ]


def test_pip_noise_is_left_out_of_the_rejection():
    from submissions.intake.dependencies import pip_error_summary

    output = (
        "WARNING: Location 'file:///somewhere/simple/nope/' is ignored: it is neither a file nor a"
        " directory.\n"
        "ERROR: Could not find a version that satisfies the requirement nope-pkg==9 (from "
        "versions: none)\n"
        "\n[notice] A new release of pip is available\n"
        "ERROR: No matching distribution found for nope-pkg==9\n"
    )
    assert pip_error_summary(output) == (
        "Could not find a version that satisfies the requirement nope-pkg==9 (from versions: "
        "none) / No matching distribution found for nope-pkg==9"
    )
    assert pip_error_summary("WARNING: x\nsomething broke\n") == "something broke"


def test_requirements_resolve_for_the_sandbox_python_not_the_hosts(tmp_path: Path) -> None:
    """numpy 1.23.5 has wheels for CPython 3.11 (the host's and the sandbox's) but none for
    3.12: a sandbox on 3.12 refuses the pin, naming its Python, though the host could install it."""
    requirements = {"requirements.txt": "numpy==1.23.5\n"}
    upload = write_zip(tmp_path / "a.zip", with_policy(**requirements))
    sandbox_311 = with_fields(Settings(), storage={"data_dir": tmp_path / "data"})
    installed = prepare_submission(
        upload,
        tmp_path / "a",
        sandbox_311.intake,
        sandbox_311.sandbox,
        sandbox_311.storage.resolved_data_dir,
    )
    assert installed.deps_dir is not None
    assert (installed.deps_dir / "numpy-1.23.5.dist-info").is_dir()
    sandbox_312 = with_fields(
        Settings(),
        storage={"data_dir": tmp_path / "data"},
        sandbox={"agent_python_version": "3.12"},
    )
    with pytest.raises(IntakeError) as caught:
        prepare_submission(
            upload,
            tmp_path / "b",
            sandbox_312.intake,
            sandbox_312.sandbox,
            sandbox_312.storage.resolved_data_dir,
        )
    assert caught.value.rule == "no-wheel" and "3.12" in str(caught.value)


def test_requirements_that_conflict_are_refused_naming_the_conflict(tmp_path: Path) -> None:
    settings = with_fields(Settings(), storage={"data_dir": tmp_path / "data"})
    text = "numpy==1.23.5\nnumpy>=2\n"
    upload = write_zip(tmp_path / "a.zip", with_policy(**{"requirements.txt": text}))
    with pytest.raises(IntakeError) as caught:
        prepare_submission(
            upload,
            tmp_path / "a",
            settings.intake,
            settings.sandbox,
            settings.storage.resolved_data_dir,
        )
    assert "numpy==1.23.5" in str(caught.value) and "numpy>=2" in str(caught.value)
    assert "conflicting" in str(caught.value)
