from __future__ import annotations

import zipfile
from pathlib import Path

import pytest

from arena.errors import IntakeError
from arena.examples import example_dir
from arena_command import app
from submissions.intake import pack_folder
from tests.cli_runner import CliRunner
from tests.submissions.zips import GOOD_POLICY


def agent_folder(root: Path, policy: str = GOOD_POLICY) -> Path:
    root.mkdir(parents=True)
    (root / "policy.py").write_text(policy)
    (root / "model").mkdir()
    (root / "model" / "weights.txt").write_text("0.5\n")
    (root / "__pycache__").mkdir()
    (root / "__pycache__" / "policy.cpython-311.pyc").write_bytes(b"\0")
    (root / ".DS_Store").write_bytes(b"\0")
    return root


def test_pack_is_deterministic_and_leaves_out_clutter(tmp_path: Path) -> None:
    folder = agent_folder(tmp_path / "agent")
    first = pack_folder(folder, tmp_path / "a.zip").read_bytes()
    (folder / "policy.py").touch()  # a newer mtime must not change the zip
    second = pack_folder(folder, tmp_path / "b.zip").read_bytes()
    assert first == second
    with zipfile.ZipFile(tmp_path / "a.zip") as archive:
        assert archive.namelist() == ["model/weights.txt", "policy.py"]


def test_pack_refuses_a_symlink(tmp_path: Path) -> None:
    folder = agent_folder(tmp_path / "agent")
    (folder / "secrets").symlink_to("/etc/passwd")
    with pytest.raises(IntakeError) as caught:
        pack_folder(folder, tmp_path / "a.zip")
    assert (caught.value.entry, caught.value.rule) == ("secrets", "symlink")


@pytest.mark.parametrize("name", ["random", "keep_lane"])
def test_cli_packs_an_example(name: str, tmp_path: Path) -> None:
    out = tmp_path / f"{name}.zip"
    arguments = ["submission", "pack", str(example_dir(name)), "--out", str(out)]
    result = CliRunner().invoke(app, arguments)
    assert result.exit_code == 0, result.output
    assert "ok" in result.output
    check = CliRunner().invoke(app, ["submission", "check", str(out)])
    assert check.exit_code == 0, check.output


def test_cli_prints_the_rejection_and_fails(tmp_path: Path) -> None:
    folder = agent_folder(tmp_path / "agent", policy="def act(obs):\n    return {}\n")
    result = CliRunner().invoke(
        app, ["submission", "pack", str(folder), "--out", str(tmp_path / "a.zip")]
    )
    assert result.exit_code == 1
    assert "policy-class" in result.output and "policy.py" in result.output
