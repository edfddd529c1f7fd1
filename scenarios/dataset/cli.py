"""`arena dataset build`: the offline-learning dataset (docs/dataset.md)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

app = typer.Typer(no_args_is_help=True)


@app.command()
def build(
    out: Annotated[Path, typer.Option(help="Folder for the Minari dataset and its manifest.")],
    scenes: Annotated[
        Path | None,
        typer.Option(help="Naturalistic scenes (default: the shipped NGSIM CommonRoad scenes)."),
    ] = None,
    public: Annotated[
        bool, typer.Option(help="Include the public set's recorded (SUMO) replays.")
    ] = True,
    exclude_suite: Annotated[
        Path | None,
        typer.Option(help="A built hidden suite: the scenes it used are left out."),
    ] = None,
) -> None:
    """Replays -> a Minari dataset (observations, actions, rewards, terminations) in OUT."""
    # deferred: CLI start-up time
    from rich.console import Console

    # deferred: CLI start-up time
    from arena.config import get_settings
    from arena.suite import public_suite_dir
    from scenarios.dataset.build import build_dataset
    from scenarios.recorded.naturalistic import NaturalisticImportError, shipped_scenes_dir

    console = Console()
    settings = get_settings()
    try:
        manifest = build_dataset(
            out,
            settings.resolved_data_dir / "cache" / "scenarios",
            scenes or shipped_scenes_dir(),
            public_suite_dir(settings) if public else None,
            exclude_suite,
            lambda name: console.print(f"collected {name}"),
        )
    except NaturalisticImportError as exc:
        raise typer.BadParameter(str(exc), param_hint="--scenes") from exc
    steps = sum(e["steps"] for e in manifest["episodes"])
    console.print(
        f"wrote {manifest['dataset_id']}: {len(manifest['episodes'])} episodes, {steps} steps, "
        f"to {out} (load with MINARI_DATASETS_PATH={out})"
    )
    if manifest["excluded_scenes"]:
        console.print(f"left out (used by the hidden suite): {manifest['excluded_scenes']}")
