"""`arena stacks` commands: organiser stacks (submissions/intake/stacks.py), built once in the
resolver sandbox and named by `stack:` in agent.yaml, by the service and by `arena evaluate`."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from arena.terminal import make_console

stacks_app = typer.Typer(no_args_is_help=True)
console = make_console()
errors = make_console(stderr=True)


@stacks_app.command("build")
def build(
    name: Annotated[str, typer.Argument(help="The stack's name (agent.yaml: `stack: NAME`).")],
    requirements: Annotated[
        Path | None,
        typer.Option(help="Its requirement lines (default: the built-in stack of that name)."),
    ] = None,
    sandbox: Annotated[
        str | None, typer.Option(help="docker or bubblewrap (default: the setting).")
    ] = None,
) -> None:
    """Resolve, download and build a stack in the resolver sandbox, replacing one of that name."""
    # deferred: CLI start-up time
    from arena.config import get_settings
    from arena.errors import IntakeError, SandboxUnavailable
    from arena.neutralise.console import safe
    from evaluator.validation import sandboxed
    from submissions.intake.stacks import BUILTIN_STACKS, build_stack

    settings = get_settings()
    if requirements is not None:
        text = requirements.read_text()
    elif name in BUILTIN_STACKS:
        text = BUILTIN_STACKS[name]
    else:
        errors.print(
            f"[bold red]no built-in stack {safe(name)}[/] (built-in: "
            f"{', '.join(BUILTIN_STACKS)}); give its lines with --requirements FILE"
        )
        raise typer.Exit(2)
    data_dir = settings.storage.resolved_data_dir
    runner = sandboxed(settings.intake, settings.sandbox, data_dir, sandbox)
    try:
        with console.status(f"building stack {name} in the resolver sandbox"):
            manifest = build_stack(name, text, settings.intake, settings.sandbox, data_dir, runner)
    except (IntakeError, SandboxUnavailable) as error:
        errors.print(f"[bold red]cannot build stack {safe(name)}[/]: {safe(str(error))}")
        raise typer.Exit(1) from error
    show(manifest)


@stacks_app.command("list")
def list_stacks() -> None:
    """The stacks built in this data folder, with what each holds."""
    # deferred: CLI start-up time
    from arena.config import get_settings
    from submissions.intake.stacks import built_stacks

    stacks = built_stacks(get_settings().storage.resolved_data_dir)
    if not stacks:
        console.print("no stack is built here (arena stacks build NAME)")
    for manifest in stacks:
        show(manifest)


def show(manifest: dict) -> None:
    size = sum(wheel["bytes"] for wheel in manifest["wheels"]) / 1024**2
    console.print(f"[bold]{manifest['name']}[/]: {len(manifest['wheels'])} wheels, {size:.0f} MiB")
    for wheel in manifest["wheels"]:
        console.print(f"  {wheel['name']}")
    for project, build in manifest["cpu_builds"].items():
        console.print(f"  {project}: the CPU build {build} (the sandbox has no GPU)")
    for sdist in manifest["built_from_source"]:
        console.print(f"  built from source in the sandbox: {sdist}")
