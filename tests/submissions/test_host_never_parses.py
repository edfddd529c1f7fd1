"""Issue 40: every byte a team sends is parsed in the intake (the sandbox, for the service); the
host receives a flat, bounded verdict and opens none of the team's files. Every zip rule applies to
every name, as stored."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from agent_runtime import intake as rules
from arena.config import Settings
from arena.errors import IntakeError, ParticipantError
from evaluator.validation import validate
from sim.interface import ActionSpace, ObservationFormat
from submissions.intake import check_zip, prepare_submission
from submissions.intake.archive import check_directory
from submissions.intake.runner import in_process
from tests.settings import with_fields
from tests.submissions.zips import renamed_entry_zip, with_policy, write_zip

ZIP_ONLY = (Settings().intake, Settings().sandbox)
DEEP_FLOW = "observation_format: " + "[" * 20_000 + "]" * 20_000 + "\n"
NUL_NAMED = {**with_policy(), "evil~name.py": "x = 1\n"}


def nul_named_zip(path: Path) -> Path:
    path.write_bytes(renamed_entry_zip(NUL_NAMED, "evil~name.py", b"evil\0name.py"))
    return path


def test_agent_yaml_nested_20000_deep_is_the_teams_error_not_a_crash(tmp_path: Path) -> None:
    upload = write_zip(tmp_path / "a.zip", with_policy(**{"agent.yaml": DEEP_FLOW}))
    with pytest.raises(IntakeError) as caught:
        check_zip(upload, *ZIP_ONLY)
    assert isinstance(caught.value, ParticipantError)
    assert (caught.value.entry, caught.value.rule) == ("agent.yaml", "agent-yaml")
    assert "line 1" in caught.value.message and "Traceback" not in str(caught.value)


def test_an_entry_whose_stored_name_holds_a_nul_is_refused(tmp_path: Path) -> None:
    upload = nul_named_zip(tmp_path / "a.zip")
    # The API's check of the directory alone, and the intake proper.
    for check in (
        lambda: check_directory(upload, Settings().intake),
        lambda: check_zip(upload, *ZIP_ONLY),
    ):
        with pytest.raises(IntakeError) as caught:
            check()
        assert caught.value.rule == "bad-name"
        assert caught.value.entry == repr("evil\0name.py")  # shown escaped, never raw


def test_a_nul_name_inside_a_nested_zip_is_refused(tmp_path: Path) -> None:
    inner = renamed_entry_zip(NUL_NAMED, "evil~name.py", b"evil\0name.py")
    upload = write_zip(tmp_path / "a.zip", with_policy(**{"inner.zip": inner}))
    with pytest.raises(IntakeError) as caught:
        check_zip(upload, *ZIP_ONLY)
    assert caught.value.rule == "bad-name"


def test_the_host_reads_the_verdict_not_the_teams_files(tmp_path: Path) -> None:
    """Once the intake has run, the submission's configuration files are gone from the host's
    view: what it prepares comes from the verdict alone."""

    def intake_then_hide_the_files(mode: str, inputs: Path, output: Path) -> dict:
        verdict = in_process(mode, inputs, output)
        for name in (rules.AGENT_YAML, rules.REQUIREMENTS, rules.EXPLANATION):
            (output / rules.SUBMISSION_DIR / name).unlink(missing_ok=True)
        return verdict

    files = with_policy(
        **{
            "agent.yaml": "action_space: Continuous  # comment\nobservation_format: 'arrays'\n",
            "explanation.md": "why it drives well",
        }
    )
    settings = with_fields(Settings(), storage={"data_dir": tmp_path / "data"})
    prepared = prepare_submission(
        write_zip(tmp_path / "a.zip", files),
        tmp_path / "sub",
        settings.intake,
        settings.sandbox,
        settings.storage.resolved_data_dir,
        runner=intake_then_hide_the_files,
        install=False,
    )
    assert prepared.interface.action_space is ActionSpace.Continuous
    assert prepared.interface.observation_format is ObservationFormat.arrays
    assert prepared.explanation == "why it drives well"


@pytest.mark.parametrize(
    "line",
    [
        "numpy; " + "(" * 20_000 + 'python_version > "3"' + ")" * 20_000,  # RecursionError once
        "numpy; " + "(" * 300 + 'python_version > "3"' + ")" * 300,
        "numpy" + " " * 2000,
    ],
    ids=["20000-deep", "300-deep", "long"],
)
def test_a_requirement_line_the_hosts_parser_could_not_take_is_refused(
    line: str, tmp_path: Path
) -> None:
    upload = write_zip(tmp_path / "a.zip", with_policy(**{"requirements.txt": line + "\n"}))
    with pytest.raises(IntakeError) as caught:
        check_zip(upload, *ZIP_ONLY)
    assert (caught.value.entry, caught.value.rule) == ("requirements.txt:1", "requirements-syntax")


@pytest.mark.parametrize(
    "text",
    [
        "a: 1e3\nb: -1\nc: .5\nd: 1_000\ne: 0x10\nf: 010\ng: -.inf\nh: ~\ni:\n",
        "a: yes\nb: Off\nc: TRUE\nd: x#y\ne: 'it''s # not a comment'\nf: \"q\\\"\\n\"\n",
        "---\n# only comments and blank lines\n\naction_space: TargetPose   # trailing\n",
    ],
)
def test_agent_yaml_reads_as_yaml_reads_it(text: str) -> None:
    assert rules.parse_agent_yaml(text) == (yaml.safe_load(text) or {})


@pytest.mark.parametrize(
    ("text", "says"),
    [
        ("a:\n  b: 1\n", "line 2: indented"),
        ("- TargetPose\n", "must be a mapping"),
        ("a: [1, 2]\n", "one plain value"),
        ("a: {b: 1}\n", "one plain value"),
        ("a: &anchor 1\n", "one plain value"),
        ("a: |\n  text\n", "one plain value"),
        ("a: b: c\n", "not nested"),
        ("a: 1\na: 2\n", "line 2: a is set twice"),
        ("a: 'open\n", "not closed"),
        ("".join(f"o{i}: 1\n" for i in range(rules.MAX_OPTIONS + 1)), "more than"),
        (f"a: {'x' * (rules.MAX_OPTION_VALUE + 1)}\n", "characters"),
        (DEEP_FLOW, "one plain value"),
    ],
    ids=lambda value: value[:24] if isinstance(value, str) else None,
)
def test_agent_yaml_beyond_a_flat_mapping_is_refused_naming_the_line(text: str, says: str) -> None:
    with pytest.raises(rules.Rejected) as caught:
        rules.parse_agent_yaml(text)
    assert caught.value.rule == "agent-yaml" and says in caught.value.message


@pytest.mark.slow  # the intake in the service's sandbox
@pytest.mark.parametrize("kind", ["bubblewrap", "docker"])
def test_the_service_refuses_both_in_the_sandbox(tmp_path: Path, kind: str) -> None:
    settings = with_fields(Settings(), storage={"data_dir": tmp_path / "data"})
    uploads = {
        "agent-yaml": write_zip(tmp_path / "deep.zip", with_policy(**{"agent.yaml": DEEP_FLOW})),
        "bad-name": nul_named_zip(tmp_path / "nul.zip"),
    }
    for rule, upload in uploads.items():
        with pytest.raises(IntakeError) as caught:
            validate(
                upload,
                tmp_path / rule,
                settings.intake,
                settings.sandbox,
                settings.storage.resolved_data_dir,
                kind=kind,
            )
        assert caught.value.rule == rule and isinstance(caught.value, ParticipantError)
