"""`arena scenarios` commands: build, list, show and verify scenario suites."""

from __future__ import annotations

from enum import StrEnum
from pathlib import Path
from typing import Annotated

import typer

app = typer.Typer(no_args_is_help=True)


class SuiteName(StrEnum):
    hidden = "hidden"
    public = "public"


def _console():
    # deferred: CLI start-up time
    from arena.terminal import make_console

    return make_console()


def progress_bar():
    # deferred: CLI start-up time
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    return Progress(
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        TextColumn("{task.fields[current]}"),
        console=_console(),
    )


def _cache_dir() -> Path:
    # deferred: CLI start-up time
    from arena.config import get_settings

    return get_settings().storage.resolved_data_dir / "cache" / "scenarios"


def _hidden_seed(seed: str | None, dev: bool) -> int:
    # deferred: CLI start-up time
    from arena.config import get_settings
    from arena.seeds import SeedError, parse_seed

    settings = get_settings()
    if seed is not None:
        try:
            return parse_seed(seed)
        except SeedError as exc:
            raise typer.BadParameter(str(exc), param_hint="--seed") from None
    if settings.suites.hidden_seed is not None:
        return settings.suites.hidden_seed
    if dev:
        return settings.suites.development_seed
    raise typer.BadParameter(
        "no hidden seed: pass --seed, set ARENA_HIDDEN_SEED_FILE (or ARENA_HIDDEN_SEED), or "
        "use --dev for the development seed (never for a real competition)",
        param_hint="--seed",
    )


class Label(StrEnum):
    """What an organiser states of a corpus's traffic (overrides the files' own ``source``)."""

    naturalistic = "naturalistic"  # recorded real traffic
    recorded = "recorded"  # a simulator's traffic


CorpusLabel = Annotated[
    Label | None,
    typer.Option(
        "--label",
        help="The corpus's traffic is naturalistic (real) or recorded (a simulator's); by "
        "default read from each file's `source` (simulators are never naturalistic).",
    ),
]
CorpusLicence = Annotated[
    Path | None,
    typer.Option(
        "--licence",
        exists=True,
        dir_okay=False,
        help="Licence file of the corpus (default: LICENSE.txt / LICENSE beside the scenes).",
    ),
]
Jobs = Annotated[int, typer.Option("--jobs", min=1, help="Processes reading scene files.")]


@app.command()
def build(
    out: Annotated[Path, typer.Option(help="Folder to write the suite into (replaced).")],
    suite: Annotated[SuiteName, typer.Option(help="Which suite.")] = SuiteName.hidden,
    seed: Annotated[
        str | None,
        typer.Option(
            help="Hidden suite seed (secret): a number or a passphrase (sha256 gives the number); "
            "pick 128 random bits, e.g. `python3 -c 'import secrets; "
            "print(secrets.token_urlsafe(24))'`. On a shared host prefer ARENA_HIDDEN_SEED_FILE: "
            "`ps` shows a command line."
        ),
    ] = None,
    dev: Annotated[bool, typer.Option(help="Hidden suite from the development seed.")] = False,
    naturalistic_dir: Annotated[
        Path | None,
        typer.Option(
            "--naturalistic-dir",
            help="Folder of CommonRoad .xml / NGSIM CSV scenes to cut one-agent replays from.",
        ),
    ] = None,
    label: CorpusLabel = None,
    licence: CorpusLicence = None,
    jobs: Jobs = 1,
) -> None:
    """Build the hidden suite (128 scenarios) or the public set into OUT with a manifest.json."""
    # deferred: CLI start-up time
    from arena.scenario import DataLabel
    from scenarios.recorded.naturalistic import NaturalisticImportError, scene_files
    from scenarios.suites import PUBLIC_SEED, SUITES, CorpusOptions, build_suite

    if suite is SuiteName.public:
        if seed is not None or dev:
            raise typer.BadParameter("the public set is always built from its committed seed")
        suite_seed = PUBLIC_SEED
    else:
        suite_seed = _hidden_seed(seed, dev)
    total = len(SUITES[suite.value]())
    with progress_bar() as progress:
        corpus = None
        if naturalistic_dir is not None:
            try:
                files = len(scene_files(naturalistic_dir))
            except NaturalisticImportError as exc:
                raise typer.BadParameter(str(exc), param_hint="--naturalistic-dir") from exc
            reading = progress.add_task("reading scenes", total=files, current="")
            corpus = CorpusOptions(
                naturalistic_dir,
                DataLabel(label.value) if label else None,
                licence,
                jobs,
                lambda name: progress.update(reading, advance=1, current=name),
            )
        task = progress.add_task(f"building {suite.value}", total=total, current="")
        try:
            manifest = build_suite(
                suite.value,
                suite_seed,
                out,
                _cache_dir(),
                lambda sid: progress.update(task, advance=1, current=sid),
                naturalistic_dir=corpus,
            )
        except NaturalisticImportError as exc:
            raise typer.BadParameter(str(exc), param_hint="--naturalistic-dir") from exc
    console = _console()
    console.print(f"wrote {len(manifest.scenarios)} scenarios and manifest.json to {out}")
    if naturalistic_dir is not None:
        from_corpus = [e for e in manifest.scenarios if e.source is not None]
        console.print(
            f"{len(from_corpus)} of them from {naturalistic_dir} "
            f"({sum(e.label == 'naturalistic' for e in from_corpus)} naturalistic), cut from "
            f"{len(manifest.naturalistic_scenes or ())} scene files"
        )
        print_corpus_report(manifest.naturalistic_skipped, manifest.naturalistic_rejected)
        for u in manifest.naturalistic_unsolved or ():
            _console().print(
                f"not finished {u['file']} {u['vehicle']}: {u['reason']}",
                markup=False,
                highlight=False,
            )


def print_corpus_report(skipped, rejected) -> None:
    """The scene files a build skipped with their reasons, and the rejected vehicles."""
    # deferred: CLI start-up time
    from scenarios.recorded.naturalistic import REJECTIONS

    console = _console()
    for s in skipped or ():
        console.print(f"skipped {s['file']}: {s['reason']}", markup=False, highlight=False)
    if rejected:
        counts = ", ".join(f"{n} {reason}" for reason, n in rejected.items())
        console.print(f"recorded vehicles not used as missions: {counts}")
        for reason in rejected:
            console.print(f"  {reason}: {REJECTIONS.get(reason, reason)}", highlight=False)


@app.command("list")
def list_(
    directory: Annotated[str, typer.Argument(help="A built suite folder, or `public` / `hidden`.")],
    as_json: Annotated[bool, typer.Option("--json", help="The rows as a JSON list.")] = False,
) -> None:
    """The scenarios of a built suite: a table on a terminal, tab-separated lines in a pipe."""
    # deferred: CLI start-up time
    from arena.terminal import make_console, print_rows

    manifest = _suite(directory).manifest
    columns = ("id", "family", "variant", "volume", "agents", "reactive", "label", "hash")
    rows = [
        (
            s.id,
            s.family.value,
            s.variant,
            s.volume,
            s.agents,
            s.reactive if as_json else ("yes" if s.reactive else "no"),
            s.label.value,
            s.hash if as_json else s.hash[:12],
            s.unsolvable_reason or "",
        )
        for s in manifest.scenarios
    ]
    print_rows(
        make_console(),
        (*columns, "unsolvable_reason"),
        rows,
        title=f"{manifest.suite} suite: {len(manifest.scenarios)} scenarios",
        as_json=as_json,
        numeric=("agents",),
    )


def _suite(directory: str | Path):
    # deferred: CLI start-up time
    from arena.config import get_settings
    from arena.errors import SuiteError
    from arena.suite import load_suite, resolve_suite

    try:
        settings = get_settings()
        return load_suite(
            resolve_suite(directory, settings.suites, settings.storage.resolved_data_dir)
        )
    except SuiteError as exc:
        raise typer.BadParameter(str(exc)) from exc


@app.command()
def show(
    scenario: Annotated[str, typer.Argument(help="Scenario id (or path to its folder).")],
    out: Annotated[Path, typer.Option(help="SVG file to write.")] = Path("scenario.svg"),
    suite_dir: Annotated[
        Path | None,
        typer.Option("--suite-dir", help="Built suite holding the id (default: public)."),
    ] = None,
    step: Annotated[int, typer.Option(help="Draw the traffic at this step.", min=0)] = 0,
) -> None:
    """Draw a scenario: map, lanes, traffic at STEP, mission starts, routes and goals."""
    # deferred: CLI start-up time
    from arena.config import get_settings
    from arena.suite import public_suite_dir
    from scenarios.picture import draw_scenario

    folder = Path(scenario)
    if not (folder / "scenario.json").exists():
        folder = (suite_dir or public_suite_dir(get_settings().suites)) / scenario
    if not (folder / "scenario.json").exists():
        raise typer.BadParameter(f"no scenario {scenario!r} in {folder.parent}")
    out.write_text(draw_scenario(folder, step))
    _console().print(f"wrote {out}")


@app.command()
def verify(
    directory: Annotated[str, typer.Argument(help="A built suite folder, or `public` / `hidden`.")],
    jobs: Annotated[int, typer.Option(help="Episodes run in parallel.", min=1)] = 1,
    only: Annotated[list[str] | None, typer.Option(help="Verify just these ids.")] = None,
) -> None:
    """Run the expert on every scenario (log replay for replays, the reference planner for
    reactive ones); record unsolved reasons in the manifest; print `solved=<k>/<n>`."""
    # deferred: CLI start-up time
    from rich.table import Table

    # deferred: CLI start-up time
    from scenarios.verify import verify_suite

    suite = _suite(directory)
    ids = [s.id for s in suite.scenarios if not only or s.id in only]
    with progress_bar() as progress:
        task = progress.add_task("verifying", total=len(ids), current="")
        results = verify_suite(
            suite.root, ids, jobs, lambda r: progress.update(task, advance=1, current=r.scenario_id)
        )
    table = Table(title="expert runs")
    table.add_column("id", no_wrap=True)
    for column in ("expert", "solved", "steps"):
        table.add_column(column)
    table.add_column("reason", overflow="fold")
    for r in results:
        table.add_row(
            r.scenario_id,
            r.expert,
            "[green]yes" if r.solved else "[red]no",
            str(r.steps),
            r.reason or "",
        )
    console = _console()
    console.print(table)
    solved = sum(r.solved for r in results)
    console.print(f"solved={solved}/{len(results)}")
