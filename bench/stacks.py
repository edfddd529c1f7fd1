"""Organiser stacks and a real agent's requirements, through the resolver sandbox.

Builds the ``ds2022`` stack (torch's CPU build, numpy 1.23.5, gym 0.26.2 from its sdist, d3rlpy
1.1.1) from the package index the host's pip is configured for (``ARENA_PACKAGE_INDEX``
overrides it), then validates, as one upload each, in the service's sandbox:

- an agent with ``stack: ds2022`` and a competition agent's ``requirements.txt`` (by default
  ``bench/data/ds2022_third_place_requirements.ported.txt``: the Driving SMARTS 2022 Track 1
  3rd-place agent's published file with only the porting ``docs/smarts-compat.md`` prescribes;
  ``--requirements FILE``, repeatable, for others, e.g. the file as published beside it);
- an agent whose ``requirements.txt`` is the one line ``torch``, which must install torch's CPU
  build.

Prints each step's time and outcome (wheels, MiB, what was built from source); the last line is
``stack_build_s=<n> stack_mib=<n> stack_upload=<ok|rule>[,...] torch_build=<version>``.

``--smoke`` (the test suite's) does the same against a package index on loopback that it builds
itself (fake wheels, a fake torch with CPU and plain builds, a small stack): nothing leaves the
machine.

    python bench/stacks.py [--sandbox bubblewrap|docker] [--requirements FILE ...] [--smoke]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from contextlib import AbstractContextManager, ExitStack
from pathlib import Path

from _package_index import build_wheel, served_index
from _prerequisites import require

from arena.config import SandboxKind, Settings
from arena.errors import IntakeError
from evaluator.sandbox.backend_registry import backend_for
from evaluator.validation import sandboxed, validate
from submissions.intake import pack_folder
from submissions.intake.dependencies import MANIFEST
from submissions.intake.stacks import BUILTIN_STACKS, build_stack

SMOKE_STACK = "torch\nsmallpkg==1.0\n"
POLICY = "class Policy:\n    def act(self, obs):\n        return {}\n"
SMOKE_TEAM_REQUIREMENTS = "otherpkg==2.0\n"
DATA = Path(__file__).parent / "data"
THIRD_PLACE_PORTED = DATA / "ds2022_third_place_requirements.ported.txt"


def smoke_index(root: Path) -> AbstractContextManager[str]:
    """A loopback index with what the smoke run installs."""
    files = root / "files"
    files.mkdir()
    build_wheel(files, "torch", "2.1.0", requires=("gpulib",))
    build_wheel(files, "gpulib", "1.0")
    build_wheel(files, "torch", "2.1.0+cpu")
    build_wheel(files, "smallpkg", "1.0")
    build_wheel(files, "otherpkg", "2.0", requires=("smallpkg==1.0",))
    return served_index(files, root / "web")


def upload(settings: Settings, work: Path, name: str, files: dict[str, str], kind: str):
    """Validate one agent zip as the service does; (seconds, the prepared submission or the
    rejection)."""
    source = work / f"{name}-src"
    source.mkdir()
    for file_name, text in {"policy.py": POLICY, **files}.items():
        (source / file_name).write_text(text)
    zip_path = pack_folder(source, work / f"{name}.zip")
    started = time.monotonic()
    try:
        outcome = validate(
            zip_path,
            work / name,
            settings.intake,
            settings.sandbox,
            settings.storage.resolved_data_dir,
            kind=kind,
        )
    except IntakeError as error:
        outcome = error
    return time.monotonic() - started, outcome


def added_wheels(upload_manifest: dict, stack_manifest: dict) -> list[dict]:
    """The wheels of an upload on a stack that the stack does not hold: what the team adds."""
    held = {wheel["sha256"] for wheel in stack_manifest["wheels"]}
    return [wheel for wheel in upload_manifest["wheels"] if wheel["sha256"] not in held]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sandbox", default="bubblewrap", choices=("bubblewrap", "docker"))
    parser.add_argument(
        "--requirements",
        type=Path,
        action="append",
        help="a competition agent's file, on the stack (repeatable; default: the 3rd-place "
        "agent's, ported)",
    )
    parser.add_argument("--smoke", action="store_true", help="a loopback index, a small stack")
    args = parser.parse_args()
    settings = Settings()
    require(backend_for(SandboxKind(args.sandbox)).unavailable_reason(settings.sandbox))
    if args.smoke:
        team_files = {"smoke": SMOKE_TEAM_REQUIREMENTS}
    else:
        paths = args.requirements or [THIRD_PLACE_PORTED]
        team_files = {path.name: path.read_text() for path in paths}
    with ExitStack() as stack, tempfile.TemporaryDirectory(prefix="arena-stacks-") as tmp:
        work = Path(tmp)
        intake: dict = {}
        stack_name, stack_text = "ds2022", BUILTIN_STACKS["ds2022"]
        if args.smoke:
            intake["package_index"] = [stack.enter_context(smoke_index(work))]
            stack_name, stack_text = "smoke", SMOKE_STACK
        settings = settings.model_copy(
            update={
                "storage": settings.storage.model_copy(update={"data_dir": work / "data"}),
                "intake": settings.intake.model_copy(update=intake),
            }
        )
        data_dir = settings.storage.resolved_data_dir
        runner = sandboxed(settings.intake, settings.sandbox, data_dir, args.sandbox)
        started = time.monotonic()
        try:
            manifest = build_stack(
                stack_name, stack_text, settings.intake, settings.sandbox, data_dir, runner
            )
        except IntakeError as error:
            print(f"stack {stack_name}: not built: {error}")
            sys.exit(1)
        build_s = time.monotonic() - started
        mib = sum(w["bytes"] for w in manifest["wheels"]) / 1024**2
        print(
            f"stack {stack_name}: {len(manifest['wheels'])} wheels, {mib:.0f} MiB, {build_s:.1f} s"
        )
        built = manifest["built_from_source"]
        print(f"  CPU builds: {manifest['cpu_builds']}; built from source: {built}")
        verdicts = []
        for index, (file_name, text) in enumerate(team_files.items()):
            seconds, on_stack = upload(
                settings,
                work,
                f"on-stack-{index}",
                {"agent.yaml": f"stack: {stack_name}\n", "requirements.txt": text},
                args.sandbox,
            )
            if isinstance(on_stack, IntakeError):
                verdicts.append(on_stack.rule)
                print(f"{file_name} on the stack: {on_stack.rule} in {seconds:.1f} s")
                print(f"  {on_stack}")
                continue
            verdicts.append("ok")
            installed = json.loads((on_stack.deps_dir / MANIFEST).read_text())
            added = added_wheels(installed, manifest)
            added_mib = sum(w["bytes"] for w in added) / 1024**2
            print(
                f"{file_name} on the stack: ok in {seconds:.1f} s, {len(added)} wheels added "
                f"({added_mib:.1f} MiB: {', '.join(w['name'] for w in added)}); built from "
                f"source: {installed['built_from_source']}"
            )
        seconds, plain = upload(
            settings, work, "torch", {"requirements.txt": "torch\n"}, args.sandbox
        )
        if isinstance(plain, IntakeError):
            print(f"a plain torch line: rejected: {plain}")
            sys.exit(1)
        builds = json.loads((plain.deps_dir / MANIFEST).read_text())["cpu_builds"]
        torch_build = builds.get("torch", "not a CPU build")
        print(f"a plain torch line: {torch_build} in {seconds:.1f} s")
        print(
            f"stack_build_s={build_s:.1f} stack_mib={mib:.0f} stack_upload={','.join(verdicts)} "
            f"torch_build={torch_build}"
        )
        if any(verdict != "ok" for verdict in verdicts) or not torch_build.endswith("+cpu"):
            sys.exit(1)


if __name__ == "__main__":
    main()
