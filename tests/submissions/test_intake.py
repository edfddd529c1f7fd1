# ruff: noqa: E501  (the table of hostile zips reads best one case per line)
from __future__ import annotations

import os
import stat
from pathlib import Path

import pytest

from arena.config import Settings
from arena.errors import IntakeError, ParticipantError
from arena.examples import example_dir
from sim.interface import ActionSpace
from submissions.intake import prepare_submission
from tests.settings import with_fields
from tests.submissions.zips import (
    GOOD_POLICY,
    bad_crc_zip,
    entry,
    gzip_bytes,
    with_policy,
    write_zip,
    zip_bytes,
)

MIB = 1024**2


@pytest.fixture
def settings(tmp_path: Path) -> Settings:
    return with_fields(Settings(), storage={"data_dir": tmp_path / "data"})


@pytest.mark.parametrize("name", ["random", "keep_lane"])
def test_examples_pass_intake_and_extract_read_only(name: str, tmp_path: Path, settings) -> None:
    prepared = prepare_submission(
        example_dir(name),
        tmp_path / "sub",
        settings.intake,
        settings.sandbox,
        settings.storage.resolved_data_dir,
    )
    assert (prepared.root / "policy.py").is_file()
    assert prepared.deps_dir is None
    assert len(prepared.sha256) == 64 and prepared.size > 0
    assert "example" in (prepared.explanation or "")
    for path in [prepared.root, *prepared.root.rglob("*")]:
        assert stat.S_IMODE(path.stat().st_mode) & 0o222 == 0, path


@pytest.mark.parametrize(
    ("create_system", "mode"),
    [
        pytest.param(3, 0o600, id="permissions without a file type (ZipFile.writestr)"),
        pytest.param(0, 0o020644, id="made on MS-DOS/Windows: high bits carry no type"),
    ],
)
def test_zips_without_unix_file_types_are_plain_files(
    create_system: int, mode: int, tmp_path: Path, settings
) -> None:
    policy = entry("policy.py", mode)
    policy.create_system = create_system
    upload = write_zip(tmp_path / "upload.zip", {policy: GOOD_POLICY})
    prepared = prepare_submission(
        upload,
        tmp_path / "sub",
        settings.intake,
        settings.sandbox,
        settings.storage.resolved_data_dir,
    )
    assert (prepared.root / "policy.py").read_text() == GOOD_POLICY


def test_agent_yaml_is_validated_into_the_interface(tmp_path: Path, settings) -> None:
    prepared = prepare_submission(
        example_dir("keep_lane"),
        tmp_path / "sub",
        settings.intake,
        settings.sandbox,
        settings.storage.resolved_data_dir,
    )
    assert prepared.interface.action_space is ActionSpace.LaneWithContinuousSpeed


def test_preparing_again_replaces_the_folder(tmp_path: Path, settings) -> None:
    zip_path = write_zip(tmp_path / "a.zip", with_policy(**{"model/w.txt": "1"}))
    first = prepare_submission(
        zip_path,
        tmp_path / "sub",
        settings.intake,
        settings.sandbox,
        settings.storage.resolved_data_dir,
    )
    write_zip(zip_path, with_policy())
    second = prepare_submission(
        zip_path,
        tmp_path / "sub",
        settings.intake,
        settings.sandbox,
        settings.storage.resolved_data_dir,
    )
    assert first.root == second.root and not (second.root / "model").exists()


def noise(size: int) -> bytes:
    return os.urandom(size)


SMALL = {"intake": {"max_unzipped_bytes": int(2.5 * MIB)}}
# (name, files or raw bytes, entry named in the error, rule, settings overrides)
REJECTIONS = [
    ("empty file", b"", "<zip>", "empty-file", {}),
    ("not a zip", b"this is a text file, not a zip\n", "<zip>", "not-a-zip", {}),
    ("no policy.py", {"agent.yaml": "action_space: TargetPose\n"}, "policy.py", "policy-missing", {}),
    ("policy in a folder", {"agent/policy.py": GOOD_POLICY}, "policy.py", "policy-missing", {}),
    ("syntax error", {"policy.py": "class Policy(:\n    pass\n"}, "policy.py", "policy-syntax", {}),
    ("no Policy class", {"policy.py": "class Agent:\n    pass\n"}, "policy.py", "policy-class", {}),
    ("zip slip", with_policy(**{"../escape.py": "x = 1"}), "../escape.py", "zip-slip", {}),
    ("deep zip slip", with_policy(**{"a/../../x.py": "1"}), "a/../../x.py", "zip-slip", {}),
    ("absolute path", with_policy(**{"/etc/cron.d/x": "x"}), "/etc/cron.d/x", "absolute-path", {}),
    ("symlink entry", {**with_policy(), entry("link", 0o120777): "/etc/passwd"}, "link", "symlink", {}),
    ("device entry", {**with_policy(), entry("tty", 0o020644): ""}, "tty", "special-file", {}),
    ("duplicate entry", {**with_policy(), entry("policy.py"): "1"}, "policy.py", "duplicate-entry", {}),
    ("misspelt agent.yaml key", with_policy(**{"agent.yaml": "action_spce: TargetPose\n"}), "agent.yaml", "agent-yaml", {}),
    ("unknown action space", with_policy(**{"agent.yaml": "action_space: Teleport\n"}), "agent.yaml", "agent-yaml", {}),
    ("agent.yaml not a mapping", with_policy(**{"agent.yaml": "- TargetPose\n"}), "agent.yaml", "agent-yaml", {}),
    ("pip option in requirements", with_policy(**{"requirements.txt": "--index-url http://x/\nsix\n"}), "requirements.txt:1", "requirements-option", {}),
    ("url in requirements", with_policy(**{"requirements.txt": "six @ https://example.org/six.whl\n"}), "requirements.txt:1", "requirements-url", {}),
    ("zip bomb", with_policy(**{"weights.bin": bytes(40 * MIB)}), "weights.bin", "compression-ratio", {}),
    ("too many entries", with_policy(**{f"f{i}.txt": "x" for i in range(6)}), "f4.txt", "max-entries", {"intake": {"max_zip_entries": 5}}),
    ("too large unzipped", with_policy(**{n: noise(900_000) for n in "abc"}), "c", "max-unzipped-bytes", SMALL),
    ("nested zip bomb", with_policy(**{"inner.zip": zip_bytes({f"{i}.bin": bytes(MIB) for i in range(3)})}), "inner.zip!2.bin", "max-unzipped-bytes", SMALL),
    ("archives nested too deep", with_policy(**{"a.zip": zip_bytes({"b.zip": zip_bytes({"c.zip": zip_bytes({"d.txt": "x"})})})}), "a.zip!b.zip!c.zip", "nested-archive", {}),
    ("nested gzip bomb", with_policy(**{"data.gz": gzip_bytes(bytes(5 * MIB))}), "data.gz (inflated)", "max-unzipped-bytes", SMALL),
    ("too large zip", with_policy(**{"noise.bin": noise(MIB + 1000)}), "<zip>", "max-zip-bytes", {"intake": {"max_zip_bytes": MIB}}),
    # Each of these gave a 500 (an uncaught exception) instead of a rule.
    ("deeply nested sum", {"policy.py": "x = " + "1+" * 100_000 + "1\nclass Policy: pass\n"}, "policy.py", "policy-too-deep", {}),
    ("deeply nested unary", {"policy.py": "x = " + "-" * 100_000 + "1\nclass Policy: pass\n"}, "policy.py", "policy-too-deep", {}),
    ("file beside a folder of its name", with_policy(**{"a": "x", "a/b.py": "y"}), "a/b.py", "file-folder-clash", {}),
    ("folder then a file of its name", with_policy(**{"a/b.py": "y", "a": "x"}), "a", "file-folder-clash", {}),
    ("300-character name", with_policy(**{"n" * 300: "x"}), "n" * 80 + "...", "name-too-long", {}),
    ("bad CRC", bad_crc_zip(with_policy(**{"weights.txt": "some weights " * 20})), "weights.txt", "corrupt-entry", {}),
    ("bad CRC in policy.py", bad_crc_zip({"policy.py": GOOD_POLICY}), "policy.py", "corrupt-entry", {}),
]  # fmt: skip


@pytest.mark.parametrize(
    ("content", "entry_name", "rule", "overrides"),
    [pytest.param(*case[1:], id=case[0]) for case in REJECTIONS],
)
def test_hostile_zips_are_rejected_naming_entry_and_rule(
    content, entry_name: str, rule: str, overrides: dict, tmp_path: Path
) -> None:
    settings = with_fields(Settings(), storage={"data_dir": tmp_path / "data"}, **overrides)
    upload = tmp_path / "upload.zip"
    if isinstance(content, bytes):
        upload.write_bytes(content)
    else:
        write_zip(upload, content)
    with pytest.raises(IntakeError) as caught:
        prepare_submission(
            upload,
            tmp_path / "sub",
            settings.intake,
            settings.sandbox,
            settings.storage.resolved_data_dir,
        )
    error = caught.value
    assert (error.entry, error.rule) == (entry_name, rule)
    assert entry_name in str(error) and rule in str(error)
    assert isinstance(error, ParticipantError)
    assert not (tmp_path / "sub").exists(), "nothing is extracted from a rejected zip"


def test_a_rejected_zip_leaves_the_previous_extraction_alone(tmp_path: Path, settings) -> None:
    good = prepare_submission(
        write_zip(tmp_path / "good.zip", with_policy()),
        tmp_path / "sub",
        settings.intake,
        settings.sandbox,
        settings.storage.resolved_data_dir,
    )
    with pytest.raises(IntakeError):
        prepare_submission(
            write_zip(tmp_path / "bad.zip", {"x.txt": "no policy"}),
            tmp_path / "sub",
            settings.intake,
            settings.sandbox,
            settings.storage.resolved_data_dir,
        )
    assert (good.root / "policy.py").is_file()


def test_folder_and_its_zip_give_the_same_submission(tmp_path: Path, settings) -> None:
    from submissions.intake import pack_folder

    from_folder = prepare_submission(
        example_dir("random"),
        tmp_path / "a",
        settings.intake,
        settings.sandbox,
        settings.storage.resolved_data_dir,
    )
    zipped = pack_folder(example_dir("random"), tmp_path / "random.zip")
    from_zip = prepare_submission(
        zipped,
        tmp_path / "b",
        settings.intake,
        settings.sandbox,
        settings.storage.resolved_data_dir,
    )
    assert from_folder.sha256 == from_zip.sha256


def test_zip_entries_keep_their_folders(tmp_path: Path, settings) -> None:
    files = with_policy(**{"model/weights.npy": b"\x93NUMPY", "model/": b""})
    files[entry("model/", 0o040755)] = files.pop("model/")
    prepared = prepare_submission(
        write_zip(tmp_path / "a.zip", files),
        tmp_path / "sub",
        settings.intake,
        settings.sandbox,
        settings.storage.resolved_data_dir,
    )
    assert (prepared.root / "model" / "weights.npy").read_bytes() == b"\x93NUMPY"


def test_policy_is_never_executed_on_the_host(tmp_path: Path, settings) -> None:
    marker = tmp_path / "ran"
    source = f"open({str(marker)!r}, 'w').write('x')\n{GOOD_POLICY}"
    prepare_submission(
        write_zip(tmp_path / "a.zip", {"policy.py": source}),
        tmp_path / "sub",
        settings.intake,
        settings.sandbox,
        settings.storage.resolved_data_dir,
    )
    assert not marker.exists()


def test_policy_name_may_be_imported_or_assigned(tmp_path: Path, settings) -> None:
    files = {"policy.py": "from agent import MyAgent as Policy\n", "agent.py": GOOD_POLICY}
    prepare_submission(
        write_zip(tmp_path / "a.zip", files),
        tmp_path / "sub",
        settings.intake,
        settings.sandbox,
        settings.storage.resolved_data_dir,
    )


def test_a_zip_failing_extraction_installs_no_requirements(tmp_path: Path) -> None:
    """Requirements used to be installed before extraction: a zip with a damaged entry left
    them behind on every rejected try, at no cost to the team's quota."""
    settings = with_fields(Settings(), storage={"data_dir": tmp_path / "data"})
    files = with_policy(**{"requirements.txt": "six==1.16.0\n", "weights.txt": "w" * 400})
    upload = tmp_path / "upload.zip"
    upload.write_bytes(bad_crc_zip(files))
    with pytest.raises(IntakeError) as caught:
        prepare_submission(
            upload,
            tmp_path / "sub",
            settings.intake,
            settings.sandbox,
            settings.storage.resolved_data_dir,
        )
    assert (caught.value.entry, caught.value.rule) == ("weights.txt", "corrupt-entry")
    assert not (tmp_path / "sub").exists()
    deps = settings.storage.resolved_data_dir / "deps"
    assert not deps.exists() or not any(deps.iterdir())


@pytest.mark.parametrize(
    ("yaml_text", "suggestion"),
    [
        ("action_spce: TargetPose\n", "did you mean 'action_space'?"),
        ("observation_raduis: 50\n", "did you mean 'observation_radius'?"),
        ("action_space: TargetPos\n", "did you mean 'TargetPose'?"),
    ],
)
def test_a_typo_in_agent_yaml_gets_the_nearest_allowed_name(
    tmp_path: Path, settings, yaml_text, suggestion
) -> None:
    upload = write_zip(tmp_path / "a.zip", with_policy(**{"agent.yaml": yaml_text}))
    with pytest.raises(IntakeError) as caught:
        prepare_submission(
            upload,
            tmp_path / "sub",
            settings.intake,
            settings.sandbox,
            settings.storage.resolved_data_dir,
        )
    assert suggestion in str(caught.value)
    assert "Extra inputs are not permitted" not in str(caught.value)
