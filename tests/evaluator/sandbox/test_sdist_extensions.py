"""An sdist with a C extension is built into a wheel by the resolver with no network (under
Docker in the builder image, never in the agent image) and imported by the agent in its sandbox;
a missing builder is ours, a C file that does not compile is the team's."""

from __future__ import annotations

import json
import re
import zipfile
from collections.abc import Iterator
from importlib.metadata import distribution
from pathlib import Path

import pytest

from arena.config import SandboxKind, Settings
from arena.errors import IntakeError, SandboxUnavailable
from bench._package_index import build_sdist, served_index
from evaluator.sandbox import start
from evaluator.validation import validate
from submissions.intake.dependencies import MANIFEST
from tests.evaluator.sandbox.agents import observation
from tests.evaluator.sandbox.conftest import usable
from tests.settings import sandbox_args, with_fields
from tests.submissions.zips import write_zip

EXTENSION = """
#include <Python.h>

static PyObject *answer(PyObject *self, PyObject *args) { return PyLong_FromLong(6 * 7); }

static PyMethodDef methods[] = {{"answer", answer, METH_NOARGS, NULL}, {NULL, NULL, 0, NULL}};
static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "fastcalc", NULL, -1, methods};

PyMODINIT_FUNC PyInit_fastcalc(void) { return PyModule_Create(&module); }
"""
SETUP = (
    "from setuptools import Extension, setup\n"
    "setup(name='fastcalc', version='1.0', "
    "ext_modules=[Extension('fastcalc', ['fastcalc.c'])])\n"
)
PYPROJECT = '[build-system]\nrequires = ["setuptools"]\nbuild-backend = "setuptools.build_meta"\n'
# The policy answers what the compiled function returns: the extension ran in the agent sandbox.
POLICY = (
    "import fastcalc\n\n"
    "class Policy:\n"
    "    def act(self, obs):\n"
    "        return {k: [float(fastcalc.answer()), 0.0] for k in obs}\n"
)


def installed_wheel(folder: Path, project: str) -> Path:
    """A wheel of ``project`` as it is installed here (pure Python): the index has no network
    behind it, so the build requirement is served from the host's own copy."""
    dist = distribution(project)
    name = dist.metadata["Name"].replace("-", "_")
    path = folder / f"{name}-{dist.version}-py3-none-any.whl"
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as archive:
        for file in dist.files or []:
            parts = Path(str(file)).parts
            if ".." in parts or "__pycache__" in parts or parts[-1] in ("INSTALLER", "RECORD"):
                continue
            archive.write(dist.locate_file(file), str(file))
        archive.writestr(f"{name}-{dist.version}.dist-info/RECORD", "")
    return path


def extension_sdist(folder: Path, version: str, source: str, project: str = "fastcalc") -> Path:
    return build_sdist(
        folder,
        project,
        version,
        {
            "setup.py": SETUP.replace("1.0", version).replace("fastcalc", project),
            "pyproject.toml": PYPROJECT,
            f"{project}.c": source.replace("fastcalc", project),
        },
    )


@pytest.fixture(scope="module")
def index(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    """A loopback index with setuptools, fastcalc 1.0 (compiles), fastcalc 2.0 and slowcalc 1.0
    (do not)."""
    root = tmp_path_factory.mktemp("index")
    files = root / "files"
    files.mkdir()
    installed_wheel(files, "setuptools")
    extension_sdist(files, "1.0", EXTENSION)
    extension_sdist(files, "2.0", EXTENSION.replace("6 * 7", "6 * 7 +"))
    extension_sdist(files, "1.0", EXTENSION.replace("6 * 7", "6 *"), project="slowcalc")
    with served_index(files, root / "web") as url:
        yield url


def settings_for(tmp_path: Path, url: str, **sandbox) -> Settings:
    return with_fields(
        Settings(),
        storage={"data_dir": tmp_path / "data"},
        intake={"package_index": [url]},
        sandbox={"init_timeout_s": 20.0, **sandbox},
    )


def validated(tmp_path: Path, settings: Settings, kind: SandboxKind, requirements: str):
    upload = write_zip(
        tmp_path / "upload.zip", {"policy.py": POLICY, "requirements.txt": requirements}
    )
    return validate(
        upload,
        tmp_path / "submission",
        settings.intake,
        settings.sandbox,
        settings.storage.resolved_data_dir,
        kind=kind,
    )


@pytest.mark.slow  # compiles in the resolver sandbox, then starts the agent
def test_an_sdist_with_a_c_extension_builds_offline_and_runs_in_the_agent_sandbox(
    kind: SandboxKind, tmp_path: Path, index: str, labels: dict[str, str]
) -> None:
    settings = settings_for(tmp_path, index)
    prepared = validated(tmp_path, settings, kind, "fastcalc==1.0\n")
    manifest = json.loads((prepared.deps_dir / MANIFEST).read_text())
    assert manifest["built_from_source"] == ["fastcalc-1.0.tar.gz"]
    # A compiled module for the agent's interpreter (CPython 3.11 in both images).
    assert [p.name for p in prepared.deps_dir.glob("fastcalc*.so")] == [
        "fastcalc.cpython-311-x86_64-linux-gnu.so"
    ]
    with start(prepared, kind=kind, labels=labels, **sandbox_args(settings)) as handle:
        assert handle.act(observation()) == {"Agent_0": [42.0, 0.0]}


@pytest.mark.slow  # compiles in the resolver sandbox
def test_a_c_file_that_does_not_compile_is_the_teams_failure_with_the_compilers_words(
    kind: SandboxKind, tmp_path: Path, index: str
) -> None:
    settings = settings_for(tmp_path, index)
    with pytest.raises(IntakeError) as caught:
        validated(tmp_path, settings, kind, "fastcalc==2.0\n")
    message = str(caught.value)
    assert caught.value.rule == "sdist-build"
    assert "building fastcalc-2.0.tar.gz into a wheel failed" in message
    assert "fastcalc.c" in message and "error" in message
    assert str(tmp_path) not in message  # no path of ours


@pytest.mark.slow  # compiles in the resolver sandbox
def test_every_sdist_that_does_not_build_is_named_in_one_rejection(
    kind: SandboxKind, tmp_path: Path, index: str
) -> None:
    settings = settings_for(tmp_path, index)
    with pytest.raises(IntakeError) as caught:
        validated(tmp_path, settings, kind, "fastcalc==2.0\nslowcalc==1.0\n")
    message = str(caught.value)
    assert caught.value.rule == "sdist-build"
    assert "building fastcalc-2.0.tar.gz, slowcalc-1.0.tar.gz into wheels failed" in message
    # Each build's own words under its name, from its compiler's error.
    for sdist, source in (("fastcalc-2.0.tar.gz", "fastcalc"), ("slowcalc-1.0.tar.gz", "slowcalc")):
        assert re.search(rf"{sdist}: / {source}\.c:\d+:\d+: error: expected expression", message)
    assert str(tmp_path) not in message


@pytest.mark.docker
def test_the_agent_image_has_no_compiler_and_the_builder_the_agents_python(
    settings: Settings,
) -> None:
    usable(SandboxKind.docker, settings)
    from evaluator.sandbox.docker_backend import docker_client

    probe = (
        "import shutil, sys\n"
        "print(sys.version_info[:2], [shutil.which(c) for c in ('cc', 'gcc', 'g++')])"
    )
    seen = {}
    for image in (settings.sandbox.agent_image, settings.sandbox.builder_image):
        output = docker_client().containers.run(
            image, ["python3", "-c", probe], network_mode="none", remove=True
        )
        seen[image] = output.decode().strip()
    agent, builder = seen.values()
    assert agent.endswith("[None, None, None]")
    assert "None" not in builder.split(")", 1)[1]
    assert agent.split(")")[0] == builder.split(")")[0]  # the same python3 minor version


@pytest.mark.docker
def test_a_missing_builder_image_is_ours_and_never_charged(tmp_path: Path, index: str) -> None:
    settings = settings_for(tmp_path, index, builder_image="driving-arena-builder:absent")
    usable(SandboxKind.docker, settings)
    with pytest.raises(SandboxUnavailable, match=r"driving-arena-builder:absent.*build-image"):
        validated(tmp_path, settings, SandboxKind.docker, "fastcalc==1.0\n")
