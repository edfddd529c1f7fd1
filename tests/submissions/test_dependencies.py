"""Requirements resolve from a package index on loopback that the tests build (fake wheels and
sdists, a fake torch with CPU and plain builds): no test reaches a real index."""

from __future__ import annotations

import json
import os
from collections.abc import Iterator
from pathlib import Path

import pytest

from agent_runtime import intake as rules
from arena.config import Settings
from arena.errors import IntakeError
from bench._package_index import (
    build_sdist,
    build_wheel,
    served_index,
    write_simple_index,
)
from evaluator.validation import sandboxed, validate
from submissions.intake import prepare_submission
from submissions.intake.dependencies import (
    MANIFEST,
    collect_garbage,
    exclusive_bytes,
    parse_requirements,
    wheel_store,
)
from submissions.intake.porting import explain_unresolved
from submissions.intake.stacks import build_stack, read_stack
from tests.settings import with_fields
from tests.submissions.zips import with_policy, write_zip

MiB = 1024**2
SECRET = "s3cret-admin-token-4f1c"
# An sdist built by its own in-tree backend (no setuptools needed offline): importing the backend
# is the participant's code running. It tries to leave a file on the host and looks for the
# secret everywhere it can read, and records what it found in the wheel it builds.
PROBE_BACKEND = """
import os, sys, zipfile
# Spelled backwards: this file itself is readable in the sandbox.
SECRET = {secret!r}[::-1]
MARKER = {marker!r}
try:
    open(MARKER, "w").write("built here")
except OSError:
    pass

def _scan():
    found, scanned = [], 0
    def look(where, data):
        nonlocal scanned
        scanned += 1
        if SECRET.encode() in data:
            found.append(where)
    look("environ", repr(dict(os.environ)).encode())
    look("argv", repr(sys.argv).encode())
    for pid in os.listdir("/proc"):
        if pid.isdigit():
            for part in ("environ", "cmdline"):
                try:
                    look(f"/proc/{{pid}}/{{part}}", open(f"/proc/{{pid}}/{{part}}", "rb").read())
                except OSError:
                    pass
    for top in ("/", ):
        for root, dirs, files in os.walk(top):
            skipped = ("/proc", "/sys", "/dev", "/usr")
            dirs[:] = [d for d in dirs if os.path.join(root, d) not in skipped]
            for name in files:
                try:
                    with open(os.path.join(root, name), "rb") as handle:
                        look(os.path.join(root, name), handle.read(4 * 1024 * 1024))
                except OSError:
                    pass
    return found, scanned

def get_requires_for_build_wheel(config_settings=None):
    return []

def build_wheel(wheel_directory, config_settings=None, metadata_directory=None):
    found, scanned = _scan()
    name = "probe-1.0-py3-none-any.whl"
    with zipfile.ZipFile(os.path.join(wheel_directory, name), "w") as w:
        w.writestr("probe/__init__.py", "FOUND = %r\\nSCANNED = %d\\n" % (found, scanned))
        info = "probe-1.0.dist-info/"
        w.writestr(info + "METADATA", "Metadata-Version: 2.1\\nName: probe\\nVersion: 1.0\\n")
        w.writestr(info + "WHEEL", "Wheel-Version: 1.0\\nTag: py3-none-any\\n")
        w.writestr("probe-1.0.dist-info/RECORD", "")
    return name
"""


def probe_sdist(folder: Path, marker: Path) -> Path:
    """An sdist built by the probe backend (its pyproject names no build requirement)."""
    return build_sdist(
        folder,
        "probe",
        "1.0",
        {
            "pyproject.toml": (
                '[build-system]\nrequires = []\nbuild-backend = "backend"\nbackend-path = ["."]\n'
            ),
            "backend.py": PROBE_BACKEND.format(secret=SECRET[::-1], marker=str(marker)),
        },
    )


@pytest.fixture(scope="module")
def index(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[str, Path]]:
    """The loopback index's URL and the host path the probe sdist tries to write."""
    root = tmp_path_factory.mktemp("index")
    files = root / "files"
    files.mkdir()
    build_wheel(files, "smallpkg", "1.0")
    build_wheel(files, "smallpkg", "1.1")
    build_wheel(files, "otherpkg", "2.0", requires=("smallpkg==1.0",))
    # A plotting library whose newest release needs a newer smallpkg than a file may pin.
    build_wheel(files, "plotlib", "3.0", requires=("smallpkg>=1.1",))
    build_wheel(files, "plotlib", "2.0", requires=("smallpkg>=1.0",))
    # torch: a plain (GPU) build that pulls a large GPU library, and CPU builds.
    build_wheel(files, "torch", "2.1.0", requires=("gpulib",))
    build_wheel(files, "gpulib", "1.0", {"gpulib/big.bin": os.urandom(3 * MiB)})
    build_wheel(files, "torch", "2.1.0+cpu")
    build_wheel(files, "torch", "2.0.0+cpu")
    # Its dependency is on no index.
    build_wheel(files, "orphanpkg", "1.0", requires=("ghostpkg>=1",))
    # The newest torch has a GPU build only: a plain line must still get a CPU one.
    build_wheel(files, "torch", "2.2.0", requires=("gpulib",))
    # A library that needs torch without naming a build (d3rlpy does).
    build_wheel(files, "needstorch", "1.0", requires=("torch>=2",))
    # Incompressible: more than the zip cap, less than a wheel's (torch's CPU build is 183 MiB).
    build_wheel(files, "bigwheel", "1.0", {"bigwheel/blob.bin": os.urandom(3 * MiB)})
    marker = root / "built-on-the-host"
    probe_sdist(files, marker)
    # A wheel whose metadata names an sdist by direct URL: pip builds it whatever --only-binary.
    with served_index(files, root / "web") as url:
        sdist_url = url.removesuffix("/simple") + "/files/probe-1.0.tar.gz"
        build_wheel(files, "lure", "1.0", requires=(f"probe @ {sdist_url}",))
        write_simple_index(files, root / "web")
        yield url, marker


def settings_for(tmp_path: Path, url: str, **intake) -> Settings:
    return with_fields(
        Settings(),
        storage={"data_dir": tmp_path / "data"},
        intake={"package_index": [url], **intake},
    )


def upload_with(tmp_path: Path, requirements: str, name: str = "a") -> Path:
    return write_zip(tmp_path / f"{name}.zip", with_policy(**{"requirements.txt": requirements}))


def validated(tmp_path: Path, settings: Settings, requirements: str, name: str = "a"):
    return validate(
        upload_with(tmp_path, requirements, name),
        tmp_path / name,
        settings.intake,
        settings.sandbox,
        settings.storage.resolved_data_dir,
        kind="bubblewrap",
    )


def test_requirement_lines_keep_their_numbers() -> None:
    assert parse_requirements("numpy >= 1.24  # fast\n\n# comment\nsix==1.16.0\n") == [
        (1, "numpy>=1.24"),
        (4, "six==1.16.0"),
    ]


@pytest.mark.parametrize(
    ("line", "rule"),
    [
        ("-r other.txt", "requirements-option"),
        ("--index-url http://x/simple", "requirements-option"),
        ("pkg @ https://example.invalid/pkg.whl", "requirements-url"),
        ("not a requirement!", "requirements-syntax"),
    ],
)
def test_options_urls_and_bad_lines_are_refused_with_their_line(line: str, rule: str) -> None:
    with pytest.raises(IntakeError) as caught:
        parse_requirements(f"six==1.16.0\n{line}\n")
    assert (caught.value.entry, caught.value.rule) == ("requirements.txt:2", rule)


def test_a_failed_resolution_is_told_in_one_round_in_the_teams_line_numbers() -> None:
    report = {
        "ok": False,
        "errors": [
            {"line": 3, "project": "panda3d", "available": "none", "suggestions": []},
            {"line": 7, "project": "plotlib", "available": "3.0, 2.0", "suggestions": ["2.0"]},
        ],
        "conflict": [
            "Cannot install plotlib==3.0 and smallpkg==1.0",
            "The conflict is caused by:",
            "The user requested smallpkg==1.0",
            "plotlib 3.0 depends on smallpkg>=1.1 \x1b[2J",
            "see /model/tmp/pip-req-build-x/requirements.txt (line 29)",
        ],
    }
    text = "# mine\n\npanda3d==1.10.9\n\n\nsmallpkg==1.0\nplotlib==9\n"
    error = explain_unresolved(report, text)
    message = error.message
    assert error.entry == "requirements.txt"
    assert "line 3 `panda3d==1.10.9`" in message and "line 7 `plotlib==9`" in message
    assert "pin one of 2.0" in message
    assert "The user requested smallpkg==1.0 (requirements.txt:6)" in message
    assert "\x1b" not in message and "\\x1b[2J" in message
    assert "/model" not in message and "pip-req-build" not in message
    assert "Panda3D" in message


@pytest.mark.slow  # the resolver sandbox (bubblewrap)
def test_requirements_resolve_in_the_sandbox_and_are_shared_by_content(
    tmp_path: Path, index: tuple[str, Path]
) -> None:
    settings = settings_for(tmp_path, index[0])
    first = validated(tmp_path, settings, "smallpkg==1.0\n", "a")
    assert first.deps_dir is not None and (first.deps_dir / "smallpkg" / "__init__.py").is_file()
    second = validated(tmp_path, settings, "otherpkg==2.0\n", "b")
    # smallpkg 1.0 is in both stacks, on disk once.
    shared = [folder / "smallpkg" / "__init__.py" for folder in (first.deps_dir, second.deps_dir)]
    assert shared[0].stat().st_ino == shared[1].stat().st_ino
    assert len(list(wheel_store(settings.storage.resolved_data_dir).iterdir())) == 2
    owners = {"team-a": {first.deps_key}, "team-b": {second.deps_key}}
    charged = exclusive_bytes(settings.storage.resolved_data_dir, owners)
    assert charged["team-a"] == 0 and charged["team-b"] > 0  # otherpkg is b's alone
    data = settings.storage.resolved_data_dir
    assert collect_garbage(data, {second.deps_key}) == 1
    assert shared[1].is_file() and len(list(wheel_store(data).iterdir())) == 2
    assert collect_garbage(data, set()) == 1
    assert not any(wheel_store(data).iterdir())


@pytest.mark.slow  # the resolver sandbox (bubblewrap)
def test_a_variable_in_a_requirement_line_never_reads_the_hosts_environment(
    tmp_path: Path, index: tuple[str, Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    """pip expands ${VAR} in requirement files: on the host, this line once returned the admin
    token in the rejection."""
    monkeypatch.setenv("ARENA_ADMIN_TOKEN", SECRET)
    settings = settings_for(tmp_path, index[0])
    with pytest.raises(IntakeError) as caught:
        validated(tmp_path, settings, "smallpkg===${ARENA_ADMIN_TOKEN}\n")
    assert SECRET not in str(caught.value)
    assert caught.value.entry == "requirements.txt:1"


@pytest.mark.slow  # the resolver sandbox (bubblewrap)
def test_an_sdist_is_built_only_in_the_sandbox_where_no_secret_is_readable(
    tmp_path: Path, index: tuple[str, Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    """A wheel whose metadata names an sdist by URL once got that sdist built on the worker, as
    root. Now its build code runs in the resolver sandboxes: it cannot write on the host, and
    finds no secret in its environment, argv or any file it can read."""
    url, marker = index
    monkeypatch.setenv("ARENA_ADMIN_TOKEN", SECRET)
    secret_file = tmp_path / "admin_token"
    secret_file.write_text(SECRET)
    monkeypatch.setenv("ARENA_ADMIN_TOKEN_FILE", str(secret_file))
    settings = settings_for(tmp_path, url)
    prepared = validated(tmp_path, settings, "lure==1.0\n")
    assert not marker.exists()
    probe = (prepared.deps_dir / "probe" / "__init__.py").read_text()
    scope: dict = {}
    exec(probe, scope)
    assert scope["FOUND"] == [] and scope["SCANNED"] > 10
    manifest = json.loads((prepared.deps_dir / MANIFEST).read_text())
    assert manifest["built_from_source"] == ["probe-1.0.tar.gz"]


@pytest.mark.slow  # the resolver sandbox (bubblewrap)
def test_every_unresolvable_line_is_reported_at_once_with_pins_that_fit_the_file(
    tmp_path: Path, index: tuple[str, Path]
) -> None:
    settings = settings_for(tmp_path, index[0])
    text = "# agent\nsmallpkg==1.0\nnothere==1.0\n\nplotlib==9\n"
    with pytest.raises(IntakeError) as caught:
        validated(tmp_path, settings, text)
    message = caught.value.message
    assert "line 3 `nothere==1.0`" in message and "line 5 `plotlib==9`" in message
    # plotlib 3.0 needs smallpkg>=1.1, which line 2 excludes: only 2.0 is suggested.
    assert "pin one of 2.0 " in message
    assert "/tmp" not in message and ".deps-" not in message


@pytest.mark.slow  # the resolver sandbox (bubblewrap)
def test_a_dependency_no_index_has_is_named_as_one(tmp_path: Path, index: tuple[str, Path]) -> None:
    settings = settings_for(tmp_path, index[0])
    with pytest.raises(IntakeError) as caught:
        validated(tmp_path, settings, "smallpkg==1.0\norphanpkg==1.0\n")
    assert caught.value.rule == "no-distribution"
    assert "ghostpkg (a dependency of a listed requirement)" in caught.value.message


@pytest.mark.slow  # the resolver sandbox (bubblewrap)
def test_a_conflict_keeps_pips_explanation_with_the_teams_lines(
    tmp_path: Path, index: tuple[str, Path]
) -> None:
    settings = settings_for(tmp_path, index[0])
    with pytest.raises(IntakeError) as caught:
        validated(tmp_path, settings, "smallpkg==1.1\notherpkg==2.0\n")
    message = caught.value.message
    assert caught.value.rule == "requirements-conflict"
    assert "The conflict is caused by" in message
    assert "The user requested smallpkg==1.1 (requirements.txt:1)" in message


@pytest.mark.slow  # the resolver sandbox (bubblewrap)
@pytest.mark.parametrize(
    ("line", "build"),
    [("torch", "2.1.0+cpu"), ("torch==2.0.0", "2.0.0+cpu"), ("needstorch==1.0", "2.1.0+cpu")],
)
def test_a_framework_installs_its_cpu_build(
    tmp_path: Path, index: tuple[str, Path], line: str, build: str
) -> None:
    settings = settings_for(tmp_path, index[0])
    prepared = validated(tmp_path, settings, f"{line}\n")
    manifest = json.loads((prepared.deps_dir / MANIFEST).read_text())
    assert manifest["cpu_builds"] == {"torch": build}
    assert not (prepared.deps_dir / "gpulib").exists()
    assert (prepared.deps_dir / "torch" / "__init__.py").read_text() == f"V = {build!r}\n"


@pytest.mark.slow  # the resolver sandbox (bubblewrap)
def test_a_wheel_larger_than_the_zip_cap_installs_and_the_wheel_cap_holds(
    tmp_path: Path, index: tuple[str, Path]
) -> None:
    """The zip's 100 MiB cap was applied to each wheel, so torch's CPU build (183 MiB) could not
    install; one wheel has its own cap."""
    settings = settings_for(tmp_path, index[0], max_zip_bytes=1 * MiB)
    prepared = validated(tmp_path, settings, "bigwheel==1.0\n")
    assert (prepared.deps_dir / "bigwheel" / "blob.bin").stat().st_size == 3 * MiB
    capped = settings_for(tmp_path / "b", index[0], max_wheel_bytes=1 * MiB)
    with pytest.raises(IntakeError) as caught:
        validated(tmp_path, capped, "bigwheel==1.0\n", "b")
    assert caught.value.rule == "max-wheel-bytes"


def test_a_wheel_of_many_small_entries_is_judged_on_its_whole_ratio(tmp_path: Path) -> None:
    """1,100 entries of 1 MiB each (every one under the ratio check's floor) once unpacked to
    1.1 GiB from a small wheel."""
    wheels = tmp_path / "wheels"
    wheels.mkdir()
    build_wheel(wheels, "padded", "1.0", {f"padded/f{n}.bin": bytes(MiB // 2) for n in range(8)})
    limits = rules.Limits(
        max_zip_bytes=MiB,
        max_unzipped_bytes=MiB,
        max_entries=100,
        max_compression_ratio=100.0,
        max_deps_bytes=64 * MiB,
        max_deps_files=100,
        max_wheel_bytes=MiB,
    )
    with pytest.raises(rules.Rejected) as caught:
        rules.unpack_wheels(wheels, tmp_path / "out", limits)
    assert caught.value.rule == "compression-ratio"


def wheel_limits() -> rules.Limits:
    return rules.Limits(
        max_zip_bytes=MiB,
        max_unzipped_bytes=MiB,
        max_entries=100,
        max_compression_ratio=200.0,
        max_deps_bytes=256 * MiB,
        max_deps_files=100,
        max_wheel_bytes=64 * MiB,
    )


def test_a_shared_library_padded_to_the_page_alignment_installs(tmp_path: Path) -> None:
    """Pillow 13's wheel (matplotlib's dependency, so the 3rd-place 2022 agent's) was rejected:
    its libXau is 2 MiB of page-alignment padding around a little code, 224:1."""
    wheels = tmp_path / "wheels"
    wheels.mkdir()
    code = os.urandom(4 * MiB)
    padded = code[:2048] + bytes(2 * MiB) + code[2048:4096]
    build_wheel(wheels, "imaging", "1.0", {"imaging.libs/libx.so": padded, "imaging/c.so": code})
    installed = rules.unpack_wheels(wheels, tmp_path / "out", wheel_limits())
    assert installed["wheels"] == ["imaging-1.0-py3-none-any.whl"]
    out = tmp_path / "out" / "imaging-1.0-py3-none-any.whl" / "imaging.libs" / "libx.so"
    assert out.read_bytes() == padded


def test_a_large_entry_of_a_wheel_is_still_judged_on_its_own_ratio(tmp_path: Path) -> None:
    """Among incompressible entries (a low whole ratio), one 20 MiB entry of zeros."""
    wheels = tmp_path / "wheels"
    wheels.mkdir()
    files = {"bomb/zeros.bin": bytes(20 * MiB), "bomb/code.so": os.urandom(8 * MiB)}
    build_wheel(wheels, "bomb", "1.0", files)
    with pytest.raises(rules.Rejected) as caught:
        rules.unpack_wheels(wheels, tmp_path / "out", wheel_limits())
    assert caught.value.rule == "compression-ratio"
    assert caught.value.entry.endswith("bomb/zeros.bin")


@pytest.mark.slow  # pip resolves from the loopback index
def test_prepared_locally_a_participant_resolves_without_the_hosts_variables(
    tmp_path: Path, index: tuple[str, Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    """On a participant's own machine the resolver is a child with a minimal environment."""
    monkeypatch.setenv("ARENA_ADMIN_TOKEN", SECRET)
    settings = settings_for(tmp_path, index[0])
    with pytest.raises(IntakeError) as caught:
        prepare_submission(
            upload_with(tmp_path, "smallpkg===${ARENA_ADMIN_TOKEN}\n"),
            tmp_path / "a",
            settings.intake,
            settings.sandbox,
            settings.storage.resolved_data_dir,
        )
    assert SECRET not in str(caught.value)
    installed = prepare_submission(
        upload_with(tmp_path, "smallpkg==1.1\n", "b"),
        tmp_path / "b",
        settings.intake,
        settings.sandbox,
        settings.storage.resolved_data_dir,
    )
    assert installed.deps_dir is not None
    assert (installed.deps_dir / "smallpkg" / "__init__.py").read_text() == "V = '1.1'\n"


@pytest.mark.slow  # the resolver sandbox (bubblewrap)
def test_an_organiser_stack_is_built_once_and_a_team_adds_to_it(tmp_path: Path) -> None:
    """`stack: mini` in agent.yaml: the stack's wheels come from its wheelhouse (the index is
    gone by then), the team's line is added, torch is the stack's CPU build."""
    files = tmp_path / "files"
    files.mkdir()
    build_wheel(files, "torch", "2.1.0", requires=("gpulib",))
    build_wheel(files, "torch", "2.1.0+cpu")
    build_wheel(files, "smallpkg", "1.0")
    build_wheel(files, "smallpkg", "1.1")
    with served_index(files, tmp_path / "web") as url:
        settings = settings_for(tmp_path, url)
        data_dir = settings.storage.resolved_data_dir
        runner = sandboxed(settings.intake, settings.sandbox, data_dir, "bubblewrap")
        manifest = build_stack(
            "mini", "torch\nsmallpkg\n", settings.intake, settings.sandbox, data_dir, runner
        )
    assert manifest["cpu_builds"] == {"torch": "2.1.0+cpu"}
    assert read_stack(data_dir, "mini").lock == ("smallpkg==1.1", "torch==2.1.0+cpu")
    (tmp_path / "local").mkdir()
    build_wheel(tmp_path / "local", "teampkg", "1.0")
    offline = with_fields(settings, intake={"package_index": [url, str(tmp_path / "local")]})
    upload = write_zip(
        tmp_path / "a.zip",
        with_policy(**{"agent.yaml": "stack: mini\n", "requirements.txt": "teampkg==1.0\n"}),
    )
    prepared = validate(
        upload, tmp_path / "a", offline.intake, offline.sandbox, data_dir, kind="bubblewrap"
    )
    deps = prepared.deps_dir
    assert {"torch", "smallpkg", "teampkg"} <= {p.name for p in deps.iterdir()}
    assert (deps / "torch" / "__init__.py").read_text() == "V = '2.1.0+cpu'\n"
    # arena evaluate's way (the resolver a child on the participant's machine): the same stack,
    # resolved afresh (the folder the service made is collected first).
    assert collect_garbage(data_dir, set()) == 1
    with served_index(files, tmp_path / "web-again") as url_again:
        again = with_fields(
            settings, intake={"package_index": [url_again, str(tmp_path / "local")]}
        )
        local = prepare_submission(
            upload, tmp_path / "local-a", again.intake, again.sandbox, data_dir
        )
    assert (local.deps_dir / "torch" / "__init__.py").read_text() == "V = '2.1.0+cpu'\n"
    unknown = write_zip(tmp_path / "b.zip", with_policy(**{"agent.yaml": "stack: ds2030\n"}))
    with pytest.raises(IntakeError) as caught:
        validate(
            unknown, tmp_path / "b", offline.intake, offline.sandbox, data_dir, kind="bubblewrap"
        )
    assert caught.value.rule == "stack" and "built: mini" in caught.value.message


@pytest.mark.slow  # the resolver sandbox (bubblewrap)
def test_every_line_the_stacks_lock_excludes_is_told_in_one_round(tmp_path: Path) -> None:
    """A 2022 file on `stack: ds2022` pinned numpy, torch, click, cloudpickle... to versions the
    stack does not hold: pip named one conflict a run, so one line was told per upload."""
    files = tmp_path / "files"
    files.mkdir()
    build_wheel(files, "torch", "2.0.0+cpu")
    build_wheel(files, "torch", "2.1.0+cpu")
    build_wheel(files, "smallpkg", "1.0")
    build_wheel(files, "smallpkg", "1.1")
    build_wheel(files, "teampkg", "1.0")
    with served_index(files, tmp_path / "web") as url:
        settings = settings_for(tmp_path, url)
        data_dir = settings.storage.resolved_data_dir
        runner = sandboxed(settings.intake, settings.sandbox, data_dir, "bubblewrap")
        stack = "torch\nsmallpkg\n"
        build_stack("mini", stack, settings.intake, settings.sandbox, data_dir, runner)
        requirements = "smallpkg==1.0\nteampkg==1.0\ntorch==2.0.0+cpu\nnosuchpkg==1.0\n"
        upload = write_zip(
            tmp_path / "a.zip",
            with_policy(**{"agent.yaml": "stack: mini\n", "requirements.txt": requirements}),
        )
        with pytest.raises(IntakeError) as caught:
            validate(
                upload,
                tmp_path / "a",
                settings.intake,
                settings.sandbox,
                data_dir,
                kind="bubblewrap",
            )
    message = caught.value.message
    assert "line 1 `smallpkg==1.0`: the stack mini holds smallpkg 1.1" in message
    assert "line 3 `torch==2.0.0+cpu`: the stack mini holds torch 2.1.0+cpu" in message
    assert "line 4 `nosuchpkg==1.0`" in message
    assert "line 2" not in message
    assert caught.value.rule == "no-distribution"


@pytest.mark.slow  # the resolver sandbox (bubblewrap)
def test_an_sdist_whose_build_needs_a_package_from_the_index_installs(tmp_path: Path) -> None:
    """kiwisolver's sdist (the 3rd-place 2022 agent's pin) builds with `cppy`: the pip that
    installs build requirements had no proxy, so `cppy` was "on no index"."""
    files = tmp_path / "files"
    files.mkdir()
    build_wheel(files, "buildhelper", "1.0", {"buildhelper/__init__.py": b"TAG = 'helped'\n"})
    backend = (
        "import os, zipfile\n"
        "import buildhelper\n"
        "def build_wheel(wheel_directory, config_settings=None, metadata_directory=None):\n"
        "    name = 'needsbuild-1.0-py3-none-any.whl'\n"
        "    with zipfile.ZipFile(os.path.join(wheel_directory, name), 'w') as w:\n"
        "        w.writestr('needsbuild/__init__.py', 'TAG = %r\\n' % buildhelper.TAG)\n"
        "        info = 'needsbuild-1.0.dist-info/'\n"
        "        w.writestr(info + 'METADATA', 'Metadata-Version: 2.1\\nName: needsbuild\\n'\n"
        "                   'Version: 1.0\\n')\n"
        "        w.writestr(info + 'WHEEL', 'Wheel-Version: 1.0\\nTag: py3-none-any\\n')\n"
        "        w.writestr(info + 'RECORD', '')\n"
        "    return name\n"
    )
    pyproject = (
        '[build-system]\nrequires = ["buildhelper"]\nbuild-backend = "backend"\n'
        'backend-path = ["."]\n'
    )
    build_sdist(files, "needsbuild", "1.0", {"pyproject.toml": pyproject, "backend.py": backend})
    with served_index(files, tmp_path / "web") as url:
        prepared = validated(tmp_path, settings_for(tmp_path, url), "needsbuild==1.0\n")
    built = prepared.deps_dir / "needsbuild" / "__init__.py"
    assert built.read_text() == "TAG = 'helped'\n"
    manifest = json.loads((prepared.deps_dir / MANIFEST).read_text())
    assert manifest["built_from_source"] == ["needsbuild-1.0.tar.gz"]
