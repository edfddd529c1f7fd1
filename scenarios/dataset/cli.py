"""`arena dataset build`: the offline-learning dataset (docs/dataset.md)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from scenarios.cli import CorpusLabel, CorpusLicence, Jobs, print_corpus_report, progress_bar

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
        typer.Option(
            help="A built hidden suite: every scene sharing a file or a recorded vehicle with it "
            "is left out."
        ),
    ] = None,
    label: CorpusLabel = None,
    licence: CorpusLicence = None,
    jobs: Jobs = 1,
) -> None:
    """Replays -> a Minari dataset (observations, actions, rewards, terminations) in OUT."""
    # deferred: CLI start-up time
    from arena.config import get_settings
    from arena.scenario import DataLabel
    from arena.suite import public_suite_dir
    from scenarios.dataset.build import DatasetError, build_dataset
    from scenarios.recorded.naturalistic import (
        NaturalisticImportError,
        scene_files,
        shipped_scenes_dir,
    )

    settings = get_settings()
    scenes = scenes or shipped_scenes_dir(settings.suites.naturalistic_dir)
    try:
        files = len(scene_files(scenes))
    except NaturalisticImportError as exc:
        raise typer.BadParameter(str(exc), param_hint="--scenes") from exc
    with progress_bar() as progress:
        reading = progress.add_task("reading scenes", total=files, current="")
        collecting = progress.add_task("collecting episodes", total=None, current="")

        def advance(name: str) -> None:
            task = reading if not progress.tasks[reading].finished else collecting
            progress.update(task, advance=1, current=name)

        try:
            manifest = build_dataset(
                out,
                settings.storage.resolved_data_dir / "cache" / "scenarios",
                scenes,
                public_suite_dir(settings.suites) if public else None,
                exclude_suite,
                advance,
                label=DataLabel(label.value) if label else None,
                licence=licence,
                jobs=jobs,
                on_sources=lambda n: progress.update(collecting, total=n),
            )
        except NaturalisticImportError as exc:
            raise typer.BadParameter(str(exc), param_hint="--scenes") from exc
        except DatasetError as exc:
            raise typer.BadParameter(str(exc)) from exc
    console = progress.console
    steps = sum(e["steps"] for e in manifest["episodes"])
    console.print(
        f"wrote {manifest['dataset_id']}: {len(manifest['episodes'])} episodes, {steps} steps, "
        f"to {out} (load with MINARI_DATASETS_PATH={Path(out).resolve()})"
    )
    for left in manifest["excluded_scenes"]:
        console.print(f"left out {left['file']}: {left['reason']}", markup=False)
    for failed in manifest["unsolved"]:
        console.print(f"not finished {failed['scene']}: {failed['reason']}", markup=False)
    print_corpus_report(manifest["skipped_scenes"], manifest["rejected_vehicles"])
