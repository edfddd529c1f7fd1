"""`arena submission` commands: pack and check a submission zip."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from arena.terminal import make_console

submission_app = typer.Typer(no_args_is_help=True)
console = make_console()
errors = make_console(stderr=True)


def report_checked(zip_path: Path, install: bool) -> None:
    """Run intake on ``zip_path`` and print the verdict; exit 1 on a rejection."""
    # deferred: CLI start-up time
    import tempfile

    # deferred: CLI start-up time
    from arena.config import get_settings
    from arena.errors import IntakeError
    from submissions.intake import check_zip, prepare_submission

    settings = get_settings()
    try:
        if install:
            # Resolving requirements can take a minute (a torch wheel): say what is going on.
            message = "checking the zip and resolving requirements.txt to wheels…"
            with (
                tempfile.TemporaryDirectory(prefix="arena-check-") as tmp,
                errors.status(message, spinner="dots"),
            ):
                prepared = prepare_submission(
                    zip_path,
                    Path(tmp) / "submission",
                    settings.intake,
                    settings.sandbox,
                    settings.storage.resolved_data_dir,
                )
                interface, sha256, size = prepared.interface, prepared.sha256, prepared.size
                notes = prepared.notes
        else:
            checked = check_zip(zip_path, settings.intake, settings.sandbox)
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
    # deferred: CLI start-up time
    from arena.errors import IntakeError
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


def init_agent(
    folder: Annotated[Path, typer.Argument(help="Folder to create (must be new or empty).")],
) -> None:
    """Write a runnable starting agent: policy.py, agent.yaml and a test to run with pytest."""
    # deferred: CLI start-up time
    from submissions.starter import FolderNotEmpty, write_starter

    try:
        files = write_starter(folder)
    except FolderNotEmpty as error:
        errors.print(f"[bold red]error:[/] {error}; choose a new folder")
        raise typer.Exit(1) from error
    for file in files:
        console.print(f"wrote {file}")
    console.print(f"next: python -m pytest {folder}   then   arena evaluate {folder}")
    console.print("observations and actions: docs/agent-interface.md")
