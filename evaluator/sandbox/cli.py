"""`arena sandbox` commands: the sandbox images, leftovers, which backends run here."""

from __future__ import annotations

from typing import Annotated

import typer

from arena.terminal import make_console

sandbox_app = typer.Typer(no_args_is_help=True)
console = make_console()
errors = make_console(stderr=True)


@sandbox_app.command("build-image")
def build_image(
    force: Annotated[bool, typer.Option(help="Rebuild even if the image exists.")] = False,
    only: Annotated[
        str | None,
        typer.Option(
            help="Only this image: `agent` (runs policies) or `builder` (the resolver's "
            "sdist builds). Default: both."
        ),
    ] = None,
) -> None:
    """Build the sandbox images offline (debootstrap + docker import): the agent runtime, and
    the builder the resolver compiles sdists in."""
    # deferred: CLI start-up time
    from arena.config import get_settings
    from arena.errors import SandboxUnavailable
    from evaluator.sandbox.image import RECIPES
    from evaluator.sandbox.image import build_image as build

    if only is not None and only not in RECIPES:
        errors.print(f"[bold red]no image {only!r}[/]: choose one of {', '.join(RECIPES)}")
        raise typer.Exit(2)
    settings = get_settings()
    for recipe in [RECIPES[only]] if only else RECIPES.values():
        try:
            with console.status(f"building the {recipe.role} image"):
                image_id = build(
                    settings.sandbox,
                    settings.storage.resolved_data_dir,
                    force=force,
                    log=console.print,
                    recipe=recipe,
                )
        except SandboxUnavailable as error:
            errors.print(f"[bold red]cannot build the {recipe.role} image[/]: {error}")
            raise typer.Exit(1) from error
        console.print(f"[green]ready[/] {recipe.name(settings.sandbox)} {image_id}")


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
    # deferred: CLI start-up time
    from arena.config import get_settings
    from evaluator.sandbox import cleanup as remove

    labels = dict(item.split("=", 1) for item in label or [])
    console.print(f"removed {remove(get_settings().sandbox, labels)} leftover sandbox(es)")


@sandbox_app.command("status")
def status() -> None:
    """Which sandbox backends can run here, and which one `auto` picks."""
    # deferred: CLI start-up time
    from arena.config import SandboxKind, get_settings
    from arena.errors import SandboxUnavailable
    from evaluator.sandbox.backend_registry import backend_for, resolve_kind
    from evaluator.sandbox.docker_backend import missing_image_reason

    config = get_settings().sandbox
    for kind in (SandboxKind.docker, SandboxKind.bubblewrap, SandboxKind.process):
        reason = backend_for(kind).unavailable_reason(config)
        note = " (no isolation: local use only)" if kind is SandboxKind.process else ""
        shown = "[green]available[/]" if reason is None else f"[red]unavailable[/]: {reason}"
        console.print(f"{kind.value:>10}: {shown}{note}")
        if kind is SandboxKind.docker and reason is None:
            # Only the resolver's sdist builds need it: its absence leaves agents running.
            missing = missing_image_reason(config.builder_image, "the resolver's sdist builder")
            console.print(f"{'':>10}  builder: {missing or '[green]' + config.builder_image}")
    try:
        console.print(f"setting {config.kind.value!r} -> {resolve_kind(None, config).value}")
    except SandboxUnavailable as error:
        errors.print(f"setting {config.kind.value!r}: {error}")
        raise typer.Exit(1) from error
