"""Porting help at intake for Driving SMARTS 2022 submissions (issue 10)."""

from __future__ import annotations

from pathlib import Path

import pytest

from arena.config import Settings
from arena.errors import IntakeError
from arena_command import app
from evaluator.validation import validate
from submissions.intake import check_zip
from submissions.intake.porting import explain_unresolved
from tests.cli_runner import CliRunner
from tests.settings import with_fields
from tests.submissions.zips import GOOD_POLICY, write_zip

# check_zip judges the zip alone: the intake's limits and the sandbox's Python.
ZIP_ONLY = (Settings().intake, Settings().sandbox)

SMARTS_POLICY = (
    GOOD_POLICY
    + """

def submitted_wrappers():
    return []
"""
)


def test_smarts_leftovers_get_notes_naming_them(tmp_path: Path) -> None:
    upload = write_zip(
        tmp_path / "a.zip", {"policy.py": SMARTS_POLICY, "config.yaml": "img_meters: 50\n"}
    )
    notes = check_zip(upload, *ZIP_ONLY).notes
    assert len(notes) == 2
    assert "submitted_wrappers()" in notes[0] and "observation_format: smarts2022" in notes[0]
    assert notes[1].startswith("config.yaml") and "agent.yaml" in notes[1]


def test_a_plain_submission_gets_no_notes(tmp_path: Path) -> None:
    # The name in a comment or string is not a definition.
    policy = GOOD_POLICY + "\n# no submitted_wrappers here\n"
    upload = write_zip(tmp_path / "a.zip", {"policy.py": policy})
    assert check_zip(upload, *ZIP_ONLY).notes == ()


def test_check_prints_the_porting_notes(tmp_path: Path) -> None:
    upload = write_zip(tmp_path / "a.zip", {"policy.py": SMARTS_POLICY})
    result = CliRunner().invoke(app, ["submission", "check", str(upload), "--no-install"])
    assert result.exit_code == 0, result.output
    assert "porting note" in result.output and "submitted_wrappers" in result.output


def test_missing_distribution_of_a_dependency_is_named_as_one() -> None:
    # The resolver's report for a package pulled in by a listed requirement.
    report = {
        "ok": False,
        "errors": [{"line": None, "project": "gym", "available": "0.26.2", "suggestions": []}],
        "conflict": [],
    }
    explained = explain_unresolved(report, "d3rlpy==1.1.1\n")
    assert explained.entry == "requirements.txt" and explained.rule == "no-distribution"
    assert "gym (a dependency of a listed requirement)" in explained.message
    assert "versions there: 0.26.2" in explained.message
    assert "pin the requirement that pulls it in" in explained.message


def test_a_smarts_requirement_without_a_distribution_names_its_line() -> None:
    """The 1st-place team's Panda3D pin: its line in the team's numbering, the versions that
    resolve with the file, and that an arena agent does not need it."""
    requirements = "# from the SMARTS 2022 submission\nsix==1.16.0\nPanda3D==1.10.9\n"
    report = {
        "ok": False,
        "errors": [
            {
                "line": 3,
                "project": "panda3d",
                "available": "1.10.14, 1.10.13",
                "suggestions": ["1.10.14", "1.10.13"],
            }
        ],
    }
    error = explain_unresolved(report, requirements)
    assert error.entry == "requirements.txt" and error.rule == "no-distribution"
    assert error.message.startswith("line 3 `Panda3D==1.10.9`: no version of panda3d")
    assert "CPython 3.11" in error.message and "pin one of 1.10.14, 1.10.13" in error.message
    assert "a Driving Arena agent does not need: remove them" in error.message


DS2022_POLICY = (
    "import gym\nimport numpy as np\n"
    "from smarts.core.utils.math import vec_to_radians\n"
    "from smarts.core.smarts import SMARTS\n"
    "from smarts.env.wrappers.format_obs import FormatObs\n\n"
    "class Policy:\n"
    "    def act(self, obs):\n"
    "        return {k: np.array([0, 0], dtype=np.float) for k in obs}\n"
)


def test_what_ds2022_agents_needed_is_named(tmp_path: Path) -> None:
    """The three published 2022 agents imported smarts and gym and used np.float: each gets a
    note saying what to do, by observation format."""
    settings = with_fields(Settings(), storage={"data_dir": tmp_path / "data"})
    native = check_zip(
        write_zip(tmp_path / "a.zip", {"policy.py": DS2022_POLICY}),
        settings.intake,
        settings.sandbox,
    )
    text = " ".join(native.notes)
    assert "smarts.core.utils.math" in text and "observation_format: smarts2022" in text
    assert "imports gym" in text
    assert "np.float" in text and "numpy==1.23.5" in text
    with pytest.raises(IntakeError) as caught:
        check_zip(
            write_zip(
                tmp_path / "b.zip",
                {
                    "policy.py": DS2022_POLICY,
                    "agent.yaml": "observation_format: smarts2022\n",
                    "requirements.txt": "numpy==1.23.5\n",
                },
            ),
            settings.intake,
            settings.sandbox,
        )
    # The simulator is not in the sandbox's smarts: rejected, naming the place; what is there
    # passes, and the gym note comes along (np.float is fine with numpy 1.23.5 pinned).
    message = caught.value.message
    assert caught.value.rule == "smarts-compat-name" and caught.value.entry == "policy.py:4"
    assert "policy.py:4 smarts.core.smarts.SMARTS" in message
    assert "vec_to_radians" not in message and "FormatObs" not in message
    assert "gym 0.21" in message and "np.float" not in message


def test_a_rejected_port_still_gets_its_notes(tmp_path: Path) -> None:
    upload = write_zip(
        tmp_path / "a.zip",
        {"policy.py": DS2022_POLICY, "agent.yaml": "observation_format: smarts2022\nbogus: 1\n"},
    )
    with pytest.raises(IntakeError) as caught:
        check_zip(upload, *ZIP_ONLY)
    assert caught.value.entry == "agent.yaml"
    assert "Porting note" in caught.value.message and "gym 0.21" in caught.value.message


SMARTS_YAML = "observation_format: smarts2022\n"


def test_a_name_the_compat_package_lacks_is_rejected_naming_each(tmp_path: Path) -> None:
    """Issue 41's reproduction (a private name of smarts.core.utils.math), an attribute read
    through an imported module and a missing module, in two files: each named with its place."""
    helpers = (
        "import smarts.core.utils.math as math_utils\n"
        "from smarts.core.colors import SceneColors\n"
        "import gym\n\n"
        "def frame(x):\n"
        "    road = SceneColors.Road.value\n"
        "    return math_utils.vec_to_radians(x), math_utils.no_such_helper(x), gym.wrappers\n"
    )
    policy = "from smarts.core.utils.math import _gen_ego_frame_matrix\n" + GOOD_POLICY
    upload = write_zip(
        tmp_path / "a.zip",
        {"policy.py": policy, "agent/helpers.py": helpers, "agent.yaml": SMARTS_YAML},
    )
    with pytest.raises(IntakeError) as caught:
        check_zip(upload, *ZIP_ONLY)
    message = caught.value.message
    assert caught.value.rule == "smarts-compat-name"
    assert "agent/helpers.py:7 smarts.core.utils.math.no_such_helper" in message
    assert "agent/helpers.py:7 gym.wrappers" in message
    assert "policy.py:1 smarts.core.utils.math._gen_ego_frame_matrix" in message
    assert "vec_to_radians" not in message and "SceneColors" not in message


def test_what_the_compat_package_has_or_the_team_brings_passes(tmp_path: Path) -> None:
    """Every name the organisers' example and the kit's wrappers import passes; a guarded import
    is a note; a submission that ships or requires its own smarts is not checked against ours."""
    policy = (
        "from smarts.core.controllers import ActionSpaceType\n"
        "from smarts.env.wrappers.format_action import FormatAction\n"
        "from smarts.env.wrappers.format_obs import FormatObs, get_spaces, intrfc_to_stdobs\n"
        "from smarts.env.wrappers.frame_stack import FrameStack\n"
        "from smarts.core.colors import Colors, SceneColors\n"
        "from smarts.core.observations import Observation\n"
        "import gym\n"
        "SPACE = gym.spaces.Box(0, 1, shape=(1,)), gym.Space, gym.logger.set_level\n"
        "try:\n"
        "    from smarts.core.smarts import SMARTS\n"
        "except ImportError:\n"
        "    SMARTS = None\n" + GOOD_POLICY
    )
    files = {"policy.py": policy, "agent.yaml": SMARTS_YAML}
    notes = check_zip(write_zip(tmp_path / "a.zip", files), *ZIP_ONLY).notes
    (guarded,) = [n for n in notes if "try that catches ImportError" in n]
    assert "policy.py:10 smarts.core.smarts.SMARTS" in guarded
    own = {"policy.py": "from smarts.core.smarts import SMARTS\n" + GOOD_POLICY}
    shipped = own | {"smarts/__init__.py": "", "agent.yaml": SMARTS_YAML}
    check_zip(write_zip(tmp_path / "b.zip", shipped), *ZIP_ONLY)
    listed = own | {"agent.yaml": SMARTS_YAML, "requirements.txt": "smarts==0.6.1\n"}
    check_zip(write_zip(tmp_path / "c.zip", listed), *ZIP_ONLY)


def test_every_python_file_is_scanned_not_only_policy_py(tmp_path: Path) -> None:
    upload = write_zip(
        tmp_path / "a.zip",
        {"policy.py": GOOD_POLICY, "agent/helpers.py": "import numpy\nX = numpy.float\n"},
    )
    notes = " ".join(check_zip(upload, *ZIP_ONLY).notes)
    assert "np.float" in notes


def test_a_port_whose_script_is_refused_still_gets_its_notes(tmp_path: Path) -> None:
    """policy.py and train.py are checked in the intake (the sandbox for the service): a port
    refused there is told what to change as well as what is wrong."""
    upload = write_zip(
        tmp_path / "a.zip", {"policy.py": DS2022_POLICY, "train.py": "def broken(:\n"}
    )
    with pytest.raises(IntakeError) as caught:
        check_zip(upload, *ZIP_ONLY)
    assert caught.value.rule == "train-syntax"
    assert "Porting note" in caught.value.message and "imports gym" in caught.value.message


@pytest.mark.slow  # the intake in the service's sandbox
@pytest.mark.parametrize("kind", ["bubblewrap", "docker"])
def test_the_service_scans_the_python_files_in_the_sandbox(tmp_path: Path, kind: str) -> None:
    """The notes of the service's intake come from the sandbox's scan, accepted or refused."""
    settings = with_fields(Settings(), storage={"data_dir": tmp_path / "data"})
    accepted = validate(
        write_zip(tmp_path / "a.zip", {"policy.py": DS2022_POLICY}),
        tmp_path / "a",
        settings.intake,
        settings.sandbox,
        settings.storage.resolved_data_dir,
        kind=kind,
    )
    assert any("smarts.core.smarts" in note for note in accepted.notes)
    refused = write_zip(
        tmp_path / "b.zip", {"policy.py": DS2022_POLICY, "train.py": "def broken(:\n"}
    )
    with pytest.raises(IntakeError) as caught:
        validate(
            refused,
            tmp_path / "b",
            settings.intake,
            settings.sandbox,
            settings.storage.resolved_data_dir,
            kind=kind,
        )
    assert caught.value.rule == "train-syntax" and "np.float" in caught.value.message
    assert not (tmp_path / "b").exists()
    private = "from smarts.core.utils.math import _gen_ego_frame_matrix\n" + GOOD_POLICY
    with pytest.raises(IntakeError) as caught:
        validate(
            write_zip(tmp_path / "c.zip", {"policy.py": private, "agent.yaml": SMARTS_YAML}),
            tmp_path / "c",
            settings.intake,
            settings.sandbox,
            settings.storage.resolved_data_dir,
            kind=kind,
        )
    assert caught.value.rule == "smarts-compat-name"
    assert "policy.py:1 smarts.core.utils.math._gen_ego_frame_matrix" in caught.value.message
