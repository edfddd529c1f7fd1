"""`arena evaluate`, `arena score` and `arena replay`: local evaluation for participants and
re-scoring for organisers."""

from __future__ import annotations

import json
import sys
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer
from rich.console import Console
from rich.markup import escape

from arena.config import SandboxKind
from arena.errors import ArenaError
from arena.neutralise.console import plain, safe
from arena.neutralise.storable import storable_text
from arena.terminal import make_console, print_rows
from evaluator.failures import (
    describe_end,
    failure_texts,
    group_identical,
    is_agent_fault,
    never_started,
    startup_error,
)
from evaluator.viewer.export import ReplayFormat

if TYPE_CHECKING:
    from arena.cpu_limits import CpuLimits
    from evaluator.runner import ScenarioOutcome
    from evaluator.summary import Summary

app = typer.Typer(no_args_is_help=True)


@app.command()
def evaluate(
    path: Annotated[Path, typer.Argument(help="The submission: a zip or a folder.")],
    suite: Annotated[
        str, typer.Option(help="`public` (the repository's public set) or a suite folder.")
    ] = "public",
    scenario: Annotated[
        list[str] | None, typer.Option(help="Only this scenario id (repeatable).")
    ] = None,
    jobs: Annotated[
        int | None, typer.Option(min=1, help="Episodes run at once (default: ARENA_JOBS).")
    ] = None,
    sandbox: Annotated[
        SandboxKind | None, typer.Option(help="Agent sandbox (default: ARENA_SANDBOX).")
    ] = None,
    out: Annotated[
        Path | None,
        typer.Option(
            help="Results folder; re-running with the same one resumes. "
            "(default: arena-results/<submission name>/<sha256 prefix>, one per version)"
        ),
    ] = None,
    profile: Annotated[str | None, typer.Option(help="Scoring profile.")] = None,
    episodes: Annotated[
        int | None,
        typer.Option(
            min=1,
            help="Episodes of each reactive scenario, each with other traffic; the evaluation "
            "takes about this many times as long (default: ARENA_EPISODES_PER_SCENARIO).",
        ),
    ] = None,
    as_json: Annotated[
        bool, typer.Option("--json", help="Print summary.json to stdout (progress to stderr).")
    ] = False,
    per_scenario: Annotated[
        bool, typer.Option("--per-scenario", help="Also a table row per scenario.")
    ] = False,
    force: Annotated[
        bool, typer.Option("--force", help="Replace the results already in the folder.")
    ] = False,
    verbose: Annotated[
        bool,
        typer.Option("--verbose", "-v", help="Every traceback of every failed scenario."),
    ] = False,
    model: Annotated[
        Path | None,
        typer.Option(
            help="A trained output of `arena train` (Track 2), mounted read-only; the policy "
            "finds it as ARENA_MODEL_DIR."
        ),
    ] = None,
) -> None:
    """Evaluate a submission on a scenario set and print its four metrics.

    Exits 1 when a scenario failed for the agent's fault (an exception, a bad action, a timeout),
    2 when the evaluation could not run, 3 when an episode failed on our side and was not
    charged (the scores leave it out: a bug of ours, said with what to do)."""
    # deferred: CLI start-up time
    from arena.config import get_settings
    from arena.suite import resolve_suite
    from evaluator.runner import EvaluationRequest
    from evaluator.runner import evaluate as run_evaluation

    settings = get_settings()
    console = make_console(stderr=as_json)
    per_submission = out is None
    out = out or Path("arena-results") / path.stem
    _print_core(console)
    progress = _RichProgress(console)
    try:
        with _exit_on_error(console):
            summary = run_evaluation(
                EvaluationRequest(
                    path,
                    resolve_suite(suite, settings.suites, settings.storage.resolved_data_dir),
                    out_dir=out,
                    per_submission=per_submission,
                    force=force,
                    scenario_ids=scenario,
                    jobs=jobs or settings.evaluation.jobs,
                    sandbox=sandbox or settings.sandbox.kind,
                    profile=profile or settings.evaluation.scoring_profile,
                    episodes_per_scenario=episodes or settings.evaluation.episodes_per_scenario,
                    model_dir=model,
                ),
                intake=settings.intake,
                config=settings.sandbox,
                data_dir=settings.storage.resolved_data_dir,
                progress=progress,
            )
    finally:
        progress.stop()
    if per_submission:
        out = out / summary.submission[:12]
    scored = any(entry.metrics is not None for entry in summary.scenarios)
    if as_json or (scored and not could_not_start(summary)):
        _report(summary, out, console, as_json, per_scenario)
    else:  # no table of meaningless scores: the errors are the result
        _print_uncharged(summary, console)
        console.print(f"results in {out} (agent logs in {out / 'logs'})")
    notes = make_console(stderr=True) if as_json else console
    explain_failures(summary, out, notes, verbose=verbose)
    over_budget = _report_agent_cpu(out, settings.sandbox.cpu_limits, notes)
    if over_budget or any(is_agent_fault(episode.agents) for _, episode in _episodes(summary)):
        raise typer.Exit(1)
    if summary.uncharged:
        explain_uncharged(summary, out, notes)
        raise typer.Exit(3)


def _print_core(console: Console) -> None:
    """Which per-step core the simulator runs (sim/compiled.py): the pure-Python reference
    (ARENA_PURE_PYTHON, or the core not built) gives the same results several times slower."""
    from sim.compiled import core_status

    core = core_status()
    if core == "compiled":
        console.print("simulator core: compiled", style="dim")
    else:
        console.print(f"[yellow]simulator core: {escape(core)}[/] (the same results, slower)")


def explain_uncharged(summary: Summary, results_dir: Path, console: Console) -> None:
    """Why the run is not a result: episodes failed on our side (arena.outcome.verdict), never
    the agent's doing, and the scores leave them out."""
    ids = summary.uncharged
    shown = ", ".join(ids[:5]) + (f" and {len(ids) - 5} more" if len(ids) > 5 else "")
    console.print(
        f"[bold red]{len(ids)} scenario(s) failed on our side[/] and were not charged: {shown}. "
        "This is a bug of Driving Arena, not of your agent; the scores leave them out. Run "
        "again with the same --out to retry them; if they fail again, please report it with "
        f"their logs ({results_dir / 'logs'})."
    )


def over_cpu_budget(results_dir: Path) -> bool:
    """The agent's episodes in ``results_dir`` used more CPU than the evaluation's budget."""
    from evaluator.runner.cpu_budget import read_agent_cpu

    used = read_agent_cpu(results_dir)
    return used is not None and used.over_budget


def _report_agent_cpu(results_dir: Path, limits: CpuLimits, console: Console) -> bool:
    """Say the CPU the agent used of the evaluation's budget (agent_cpu.json); True when it
    passed the budget, so the remaining episodes were not run (the agent's fault)."""
    from evaluator.runner.cpu_budget import read_agent_cpu

    used = read_agent_cpu(results_dir)
    if used is None:
        return False
    if used.over_budget:
        message = limits.overridden(evaluation_s=used.budget_s).budget_exceeded(
            used.used_s, len(used.episodes)
        )
        console.print(f"[red]CPU budget exceeded[/]: {escape(message)}")
        return True
    console.print(
        f"agent CPU: {used.used_s:.1f} s of this evaluation's budget of {used.budget_s:g} s",
        style="dim",
    )
    return False


@app.command()
def train(
    path: Annotated[Path, typer.Argument(help="The submission (a zip or a folder) with train.py.")],
    dataset: Annotated[
        Path, typer.Option(help="The dataset folder of `arena dataset build`, mounted read-only.")
    ],
    out: Annotated[Path, typer.Option(help="The output folder (new or empty): the model.")],
    sandbox: Annotated[
        SandboxKind | None, typer.Option(help="Sandbox (default: ARENA_SANDBOX).")
    ] = None,
    timeout: Annotated[
        float | None,
        typer.Option(min=1, help="Wall-time budget [s] (default: ARENA_TRAIN_TIMEOUT_S)."),
    ] = None,
    seed: Annotated[
        int,
        typer.Option(min=0, help="ARENA_TRAIN_SEED, as the service sets it (seeds 0, 1, ...)."),
    ] = 0,
) -> None:
    """Run train.py in the sandbox exactly as the service does (Track 2); then
    `arena evaluate PATH --model OUT`. Its output (the tail the service keeps too) is printed
    and saved beside the model as OUT.train.log, never inside it: the model folder is what is
    evaluated and hashed.

    Exits 1 when the training failed (its named reason and log tail are printed), 2 when it
    could not run."""
    # deferred: CLI start-up time
    import tempfile

    from arena.config import get_settings
    from evaluator.training import train as run_training
    from submissions.intake import prepare_submission

    settings = get_settings()
    training = settings.training
    if timeout is not None:
        training = training.model_copy(update={"train_timeout_s": timeout})
    console = make_console()
    with _exit_on_error(console), tempfile.TemporaryDirectory(prefix="arena-train-") as tmp:
        Path(tmp).chmod(0o755)  # the sandbox user must enter the submission
        submission = prepare_submission(
            path,
            Path(tmp) / "submission",
            settings.intake,
            settings.sandbox,
            settings.storage.resolved_data_dir,
        )
        with console.status("training") as status:

            def progress(elapsed: float, log: str) -> bool:
                last = log.strip().splitlines()[-1:] or [""]
                status.update(f"training {elapsed:.0f} s  {safe(last[0][:100])}")
                return True

            result = run_training(
                submission,
                dataset,
                out,
                training=training,
                config=settings.sandbox,
                data_dir=settings.storage.resolved_data_dir,
                kind=sandbox,
                on_progress=progress,
                seed=seed,
            )
    log_file = out.parent / f"{out.name}.train.log"
    log_file.write_text(storable_text(result.log))
    console.print(plain(result.log), highlight=False, markup=False)
    if not result.ok:
        console.print(f"[bold red]{result.failure}[/]: {safe(result.detail)}")
        console.print(f"train.py's output: {escape(str(log_file))}")
        raise typer.Exit(1)
    console.print(
        f"trained in {result.elapsed_s:.1f} s: {result.output_bytes} bytes in {out}; "
        f"train.py's output in {log_file}; now `arena evaluate {path} --model {out}`",
        markup=False,
        highlight=False,
    )


@app.command()
def compare(
    a: Annotated[Path, typer.Argument(help="A results folder of `arena evaluate` (A).")],
    b: Annotated[Path, typer.Argument(help="Another results folder (B).")],
    as_json: Annotated[bool, typer.Option("--json", help="The comparison as JSON.")] = False,
) -> None:
    """Two results folders side by side: the four metrics with B - A and whether the completion
    intervals overlap, per family, and the episodes that ended differently. (Two submissions of
    the service: `arena admin compare ID ID`.)"""
    from evaluator.compare import print_comparison, side_of_summary
    from evaluator.summary import SUMMARY_FILE, read_summary

    console = make_console()
    sides = []
    for folder in (a, b):
        if not (folder / SUMMARY_FILE).is_file():
            console.print(
                f"[bold red]error:[/] {escape(str(folder))} has no {SUMMARY_FILE} (give the "
                "folder `arena evaluate` printed as 'results in ...')"
            )
            raise typer.Exit(2)
        sides.append(side_of_summary(str(folder), read_summary(folder)))
    print_comparison(console, *sides, as_json=as_json)


@app.command()
def score(
    results_dir: Annotated[Path, typer.Argument(help="A results folder of `arena evaluate`.")],
    profile: Annotated[str | None, typer.Option(help="Scoring profile.")] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print summary.json to stdout.")] = False,
    per_scenario: Annotated[
        bool, typer.Option("--per-scenario", help="Also a table row per scenario.")
    ] = False,
) -> None:
    """Re-score stored episode records (no simulation) and rewrite summary.json."""
    # deferred: CLI start-up time
    from arena.config import get_settings
    from evaluator.runner import score_results_dir
    from evaluator.scoring import load_profile
    from evaluator.summary import SUMMARY_FILE, write_summary

    console = make_console(stderr=as_json)
    if not (results_dir / SUMMARY_FILE).exists():
        console.print(f"[bold red]error:[/] {escape(str(results_dir))} has no {SUMMARY_FILE}")
        raise typer.Exit(2)
    with _exit_on_error(console):
        summary = score_results_dir(
            results_dir, load_profile(profile or get_settings().evaluation.scoring_profile)
        )
    write_summary(summary, results_dir)
    _report(summary, results_dir, console, as_json, per_scenario)


@app.command()
def replay(
    source: Annotated[
        Path, typer.Argument(help="An episode record (.npz) or an `arena evaluate` results folder.")
    ],
    scenario_id: Annotated[
        str | None,
        typer.Argument(help="The scenario, when SOURCE is a results folder of several."),
    ] = None,
    fmt: Annotated[
        ReplayFormat,
        typer.Option(
            "--format",
            help="html: the animated replay page in one offline file; gif, mp4: a video "
            "following the first agent; svg: one still picture of the whole episode.",
        ),
    ] = ReplayFormat.html,
    out: Annotated[
        Path | None, typer.Option(help="File to write [default: SCENARIO_ID.FORMAT].")
    ] = None,
    suite: Annotated[
        str, typer.Option(help="Suite folder holding the scenario's map, or `public`.")
    ] = "public",
    every: Annotated[
        int, typer.Option(min=1, help="gif/mp4: draw every N-th step (N x faster, smaller).")
    ] = 1,
) -> None:
    """Watch one episode: an animated page (open it in a browser), a GIF or MP4 video, or a still
    SVG picture, with the map, every vehicle, the ego's speed and its events."""
    # deferred: CLI start-up time
    from arena.config import get_settings
    from arena.suite import resolve_suite
    from evaluator.viewer.export import find_record, write_replay

    settings = get_settings()
    console = make_console(stderr=True)
    with _exit_on_error(console):
        record = find_record(source, scenario_id)
        out = out or Path(f"{scenario_id or record.stem}.{fmt.value}")
        with _FrameProgress(console) as progress:
            write_replay(
                record,
                resolve_suite(suite, settings.suites, settings.storage.resolved_data_dir),
                fmt,
                out,
                every=every,
                on_frames=progress.start,
            )
    console.print(f"wrote {escape(str(out))}")


@contextmanager
def _exit_on_error(console: Console) -> Iterator[None]:
    """Any error of ours (a bad suite, profile, record or submission; a sandbox that cannot
    start) is one line on the console and exit code 2: the command could not run."""
    try:
        yield
    except ArenaError as exc:
        console.print(f"[bold red]error:[/] {escape(str(exc))}")
        raise typer.Exit(2) from None


class _FrameProgress:
    """A bar of frames drawn, shown once a video starts rendering."""

    def __init__(self, console: Console) -> None:
        # deferred: CLI start-up time
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn

        self.bar = Progress(
            TextColumn("[bold]drawing frames"), BarColumn(), MofNCompleteColumn(), console=console
        )
        self.started = False

    def start(self, total: int) -> Callable[[], None]:
        task = self.bar.add_task("frames", total=total)
        self.bar.start()
        self.started = True
        return lambda: self.bar.advance(task)

    def __enter__(self) -> _FrameProgress:
        return self

    def __exit__(self, *exc: object) -> None:
        if self.started:
            self.bar.stop()


def _episodes(summary: Summary) -> list[tuple[str, object]]:
    """Every episode of the summary with its name (the scenario id when it ran once)."""
    # deferred: CLI start-up time
    from evaluator.runner.results import stored_episodes

    return [
        (key.name, episode)
        for entry in summary.scenarios
        for key, episode in stored_episodes(entry)
    ]


class _RichProgress:
    """Episodes done/total, agent failures and driving outcomes so far (a resumed run's earlier
    episodes counted too) and ETA, on the console given."""

    def __init__(self, console: Console) -> None:
        # deferred: CLI start-up time
        from rich.progress import (
            BarColumn,
            MofNCompleteColumn,
            Progress,
            TextColumn,
            TimeElapsedColumn,
            TimeRemainingColumn,
        )

        self.bar = Progress(
            TextColumn("[bold]evaluating"),
            BarColumn(),
            MofNCompleteColumn(),
            TextColumn(
                "agent failures {task.fields[faults]}  goal not reached {task.fields[missed]}"
                "  uncharged {task.fields[uncharged]}"
            ),
            TimeElapsedColumn(),
            TextColumn("ETA"),
            TimeRemainingColumn(),
            console=console,
        )
        self.task = None
        self.counts = {"faults": 0, "missed": 0, "uncharged": 0}

    def started(self, total: int, done: Sequence[ScenarioOutcome]) -> None:
        for outcome in done:
            self._count(outcome)
        self.bar.start()
        self.task = self.bar.add_task("evaluating", total=total, completed=len(done), **self.counts)

    def _count(self, outcome: ScenarioOutcome) -> None:
        # deferred: CLI start-up time
        from arena.outcome import ScenarioStatus

        if outcome.status != ScenarioStatus.done:
            self.counts["uncharged"] += 1
        elif is_agent_fault(outcome.agents):
            self.counts["faults"] += 1
        elif not all(agent.reached_goal for agent in outcome.agents):
            self.counts["missed"] += 1

    def finished(self, outcome: ScenarioOutcome) -> None:
        self._count(outcome)
        self.bar.update(self.task, advance=1, **self.counts)

    def stop(self) -> None:
        self.bar.stop()


def format_metrics(metrics) -> tuple[str, str, str, str]:
    """The four metrics as printed everywhere (web pages too: arena/figures.py); "—" where no
    agent drove a step (nothing measured, never 0, the best value)."""
    # deferred: CLI start-up time
    from arena.figures import METRICS, metric_text

    if metrics is None:
        return ("-", "-", "-", "-")
    return tuple(metric_text(name, getattr(metrics, name)) for name in METRICS)


def _report(
    summary: Summary, results_dir: Path, console: Console, as_json: bool, per_scenario: bool
) -> None:
    if as_json:
        sys.stdout.write(json.dumps(summary.to_dict(), indent=2) + "\n")
        return
    profile = summary.profile
    counts: dict[str, int] = {}
    for entry in summary.scenarios:
        if entry.metrics is not None:
            counts[entry.family] = counts.get(entry.family, 0) + 1
    rows = [("all", sum(counts.values()), summary.metrics, "")]
    rows += [(family, counts[family], m, "") for family, m in summary.families.items()]
    columns = ("set", "scenarios", "completion", "time", "humanness", "rules")
    if per_scenario:
        columns += ("outcome",)
        rows += [
            (entry.id, 1, entry.metrics, _scenario_outcome(entry)) for entry in summary.scenarios
        ]
    print_rows(
        console,
        columns,
        [
            (name, n, *format_metrics(metrics), *((outcome or "-",) if per_scenario else ()))
            for name, n, metrics, outcome in rows
        ],
        title=f"{summary.suite} - scoring profile {profile.name} v{profile.version}",
        numeric=("scenarios", "completion", "time", "humanness", "rules"),
    )
    console.print("All four are errors: smaller is better.", style="dim")
    _print_interval(summary, console)
    _print_outcomes(summary, console)
    _print_uncharged(summary, console)
    if not summary.complete and not could_not_start(summary) and not over_cpu_budget(results_dir):
        console.print("[bold yellow]incomplete:[/] re-run with the same --out to finish")
    console.print(f"results in {results_dir} (agent logs in {results_dir / 'logs'})")


def _print_uncharged(summary: Summary, console: Console) -> None:
    for scenario_id in summary.uncharged:
        entry = next(e for e in summary.scenarios if e.id == scenario_id)
        error = safe(entry.error)
        console.print(f"[red]not charged[/] {scenario_id} ({entry.status}): {error}")


def _scenario_outcome(entry) -> str:
    """How a scenario ended, for --per-scenario: each episode's agents' reasons, or the status
    of a scenario that was not charged."""
    from evaluator.compare import outcome_text
    from evaluator.runner.results import stored_episodes

    texts = [
        outcome_text([a.reason for a in episode.agents], str(episode.status))
        for _, episode in stored_episodes(entry)
    ]
    return "; ".join(texts)


def _print_outcomes(summary: Summary, console: Console) -> None:
    """Each episode that did not reach its goal, saying whether the agent failed as a program
    (its fault: exit code 1) or drove into a driving outcome (a collision, off road: scored,
    not an error of the program), with the totals."""
    reached = driving = faults = 0
    for name, episode in _episodes(summary):
        missed = [a for a in episode.agents if not a.reached_goal]
        if not missed:
            reached += episode.status == "done"
            continue
        reasons = ", ".join(describe_end(a) for a in missed)
        if is_agent_fault(missed):
            faults += 1
            console.print(f"[red]agent failure[/] {name}: {reasons}")
        else:
            driving += 1
            console.print(f"[yellow]goal not reached[/] {name}: {reasons}")
    console.print(
        f"episodes: {reached} reached the goal, {driving} ended by a driving outcome, "
        f"{faults} by an agent failure, {len(summary.uncharged)} not charged"
    )


def _print_interval(summary: Summary, console: Console) -> None:
    interval = summary.completion_interval()
    if interval is None:
        return
    n = summary.episodes_per_scenario
    runs = f"{n} episodes of each reactive scenario" if n > 1 else "one episode per scenario"
    # deferred: CLI start-up time
    from arena.figures import interval_text, metric_text

    console.print(
        f"completion {metric_text('completion', summary.metrics.completion)}, 95% interval "
        f"{interval_text(interval.low, interval.high)} (bootstrap over scenarios and episodes; "
        f"{runs})"
    )


def could_not_start(summary: Summary) -> bool:
    """Every episode that ran shows the agent failing before its first step, and the run
    stopped early because of it."""
    ran = [e for _, e in _episodes(summary) if e.status == "done"]
    return not summary.complete and bool(ran) and all(never_started(e.agents) for e in ran)


def explain_failures(
    summary: Summary, results_dir: Path, console: Console, *, verbose: bool
) -> None:
    """The tracebacks behind the failures, from the agent logs: the first of each failed
    scenario (``verbose``: all of them), identical ones printed once with their scenarios."""
    failed = [name for name, e in _episodes(summary) if is_agent_fault(e.agents)]
    logs = {name: _read_log(results_dir, name) for name in failed}
    if could_not_start(summary):
        ran = [name for name, e in _episodes(summary) if e.status == "done"]
        error = startup_error(logs.get(ran[0], ""))
        console.print(
            f"[bold red]your agent could not start[/] (stopped after {len(ran)} scenarios, "
            "every one failed the same way before its first step):"
        )
        console.print(safe(error), highlight=False)
        if "ModuleNotFoundError" in error:
            console.print(
                "a package your policy imports is missing: list it in requirements.txt "
                "(docs/submissions.md)"
            )
        return
    found = []
    for name in failed:
        found += [(name, text) for text in failure_texts(logs[name], every=verbose)]
    for group in group_identical(found):
        n = len(group.scenarios)
        where = ", ".join(group.scenarios[:5]) + (f" and {n - 5} more" if n > 5 else "")
        times = f" ({n} scenarios)" if n > 1 else ""
        console.print(f"[bold red]failure[/]{times} in {where}:")
        console.print(safe(group.text), highlight=False)
    if found and not verbose:
        console.print("(--verbose for every traceback; full logs in the logs folder)", style="dim")


def _read_log(results_dir: Path, scenario_id: str) -> str:
    path = results_dir / "logs" / f"{scenario_id}.txt"
    return path.read_text(errors="replace") if path.exists() else ""
