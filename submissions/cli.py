"""`arena submission` and `arena sandbox` commands."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console

submission_app = typer.Typer(no_args_is_help=True)
sandbox_app = typer.Typer(no_args_is_help=True)
console = Console()
errors = Console(stderr=True)


def report_checked(zip_path: Path, install: bool) -> None:
    """Run intake on ``zip_path`` and print the verdict; exit 1 on a rejection."""
    import tempfile

    from evaluator.errors import IntakeError
    from submissions.intake import check_zip, prepare_submission

    try:
        if install:
            with tempfile.TemporaryDirectory(prefix="arena-check-") as tmp:
                prepared = prepare_submission(zip_path, Path(tmp) / "submission")
                interface, sha256, size = prepared.interface, prepared.sha256, prepared.size
                notes = prepared.notes
        else:
            checked = check_zip(zip_path)
            interface, sha256, size = checked.interface, checked.sha256, checked.size
            notes = checked.notes
    except IntakeError as error:
        errors.print(f"[bold red]rejected[/]: {error.entry}: {error.message}")
        errors.print(f"  rule: [yellow]{error.rule}[/] (see docs/submissions.md)")
        raise typer.Exit(1) from error
    console.print(f"[bold green]ok[/] {zip_path} ({size / 1024:.1f} KiB, sha256 {sha256[:12]})")
    console.print(f"  action space: {interface.action_space.value}")
    for note in notes:
        console.print(f"  [yellow]porting note[/]: {note}")


@submission_app.command("pack")
def pack(
    folder: Annotated[Path, typer.Argument(help="Folder holding policy.py (and agent.yaml, ...).")],
    out: Annotated[Path, typer.Option("--out", "-o", help="Zip to write.")] = Path("agent.zip"),
    install: Annotated[
        bool, typer.Option(help="Also resolve requirements.txt to wheels, as the service will.")
    ] = True,
) -> None:
    """Zip a submission folder (deterministically, without caches) and run the intake checks."""
    from evaluator.errors import IntakeError
    from submissions.intake import pack_folder

    try:
        pack_folder(folder, out)
    except IntakeError as error:
        errors.print(f"[bold red]cannot pack[/]: {error.entry}: {error.message} [{error.rule}]")
        raise typer.Exit(1) from error
    report_checked(out, install)


@submission_app.command("check")
def check(
    zip_path: Annotated[Path, typer.Argument(help="Submission zip to check.")],
    install: Annotated[
        bool, typer.Option(help="Also resolve requirements.txt to wheels, as the service will.")
    ] = True,
) -> None:
    """Run the service's intake checks on a zip without uploading it."""
    report_checked(zip_path, install)


@sandbox_app.command("build-image")
def build_image(
    force: Annotated[bool, typer.Option(help="Rebuild even if the image exists.")] = False,
) -> None:
    """Build the agent runtime image offline (debootstrap + docker import)."""
    from evaluator.errors import SandboxUnavailable
    from evaluator.sandbox.image import build_image as build

    try:
        with console.status("building the agent runtime image"):
            image_id = build(force=force, log=console.print)
    except SandboxUnavailable as error:
        errors.print(f"[bold red]cannot build the image[/]: {error}")
        raise typer.Exit(1) from error
    console.print(f"[green]ready[/] {image_id}")


@sandbox_app.command("cleanup")
def cleanup(
    label: Annotated[
        list[str] | None, typer.Option(help="Only sandboxes with this KEY=VALUE label.")
    ] = None,
) -> None:
    """Kill and remove leftover agent containers and processes.

    Without --label this removes every agent sandbox on this host: run it when no worker is
    evaluating, or pass the labels of the evaluation to clean up after.
    """
    from evaluator.sandbox import cleanup as remove

    labels = dict(item.split("=", 1) for item in label or [])
    console.print(f"removed {remove(labels)} leftover sandbox(es)")


@sandbox_app.command("status")
def status() -> None:
    """Which sandbox backends can run here, and which one `auto` picks."""
    from arena.config import SandboxKind, get_settings
    from evaluator.errors import SandboxUnavailable
    from evaluator.sandbox import backend, resolve_kind

    settings = get_settings()
    for kind in (SandboxKind.docker, SandboxKind.bubblewrap, SandboxKind.process):
        reason = backend(kind).unavailable_reason(settings)
        note = " (no isolation: local use only)" if kind is SandboxKind.process else ""
        shown = "[green]available[/]" if reason is None else f"[red]unavailable[/]: {reason}"
        console.print(f"{kind.value:>10}: {shown}{note}")
    try:
        console.print(f"setting {settings.sandbox.value!r} -> {resolve_kind().value}")
    except SandboxUnavailable as error:
        errors.print(f"setting {settings.sandbox.value!r}: {error}")
        raise typer.Exit(1) from error
