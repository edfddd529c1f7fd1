"""The lines `arena admin submissions show` writes about a submission, before its attempts'
tables: what it is, where it stands, its timings, metrics, seeds and reproducibility manifest."""

from __future__ import annotations

from arena.figures import interval_text, metric_text
from server.commands.console import moment_text


def detail_lines(view, progress) -> list[tuple[str, str]]:
    """(name, value) lines of a submission's detail (``view``, the team's view of it) with the
    organisers' exact ``progress``."""
    m = view.metrics
    return [
        ("submission", f"{view.id} by {view.team}: {view.method_name} ({view.track})"),
        ("phase", view.phase),
        ("status", f"{view.status} {view.status_reason}".strip()),
        ("progress", f"{progress.done}/{progress.total}"),
        ("submitted", moment_text(view.created_at)),
        ("timings", _timings(view)),
        ("rank", _rank_text(view.standing)),
        ("file", f"sha256 {view.file_sha256}, {view.file_size} bytes"),
        (
            "metrics",
            "-"
            if m is None
            else f"completion {metric_text('completion', m.completion)}"
            f"{_interval_text(view.completion_interval)}, time {metric_text('time', m.time)}, "
            f"humanness {metric_text('humanness', m.humanness)}, "
            f"rules {metric_text('rules', m.rules)}",
        ),
        ("episodes", f"{view.episodes_per_scenario} per reactive scenario"),
        *_seed_rows(view.seeds),
        *_manifest_rows(view.manifest, scored=m is not None),
    ]


def _seed_rows(seeds) -> list[tuple[str, str]]:
    """A submission scored over several training seeds: their spread and each one's."""
    if seeds is None:
        return []
    each = ", ".join(f"{s.seed}: {metric_text('completion', s.completion)}" for s in seeds.per_seed)
    spread = seeds.ignores_seed or (
        f"completion from {metric_text('completion', seeds.completion_min)} "
        f"to {metric_text('completion', seeds.completion_max)} "
        f"(std {metric_text('completion', seeds.completion_std)})"
    )
    return [("seeds", f"{seeds.count}, {spread}; per seed {each}")]


def _timings(view) -> str:
    took = "" if view.duration_s is None else f", took {_duration(view.duration_s)}"
    return (
        f"queued {moment_text(view.queued_at)}, started {moment_text(view.started_at)}, "
        f"finished {moment_text(view.finished_at)}{took}"
    )


def _duration(seconds: float) -> str:
    minutes, secs = divmod(round(seconds), 60)
    hours, minutes = divmod(minutes, 60)
    return f"{hours}h{minutes:02d}m{secs:02d}s" if hours else f"{minutes}m{secs:02d}s"


def _rank_text(standing) -> str:
    if standing is None or standing.rank is None:
        return "not ranked"
    return (
        f"team ranks {standing.rank} of {standing.teams_ranked} "
        f"(with submission {standing.ranked_submission_id}); {standing.statistics}"
    )


def _manifest_rows(manifest, *, scored: bool) -> list[tuple[str, str]]:
    """The reproducibility manifest, in the lines of `submissions show` (docs/scoring.md)."""
    if manifest is None:
        why = "scored before manifests were kept" if scored else "not scored"
        return [("manifest", f"- ({why})")]
    software = "; ".join(
        f"arena {e.arena}, Python {e.python}, numpy {e.numpy}, SUMO {e.sumo}, {e.sandbox}"
        + (f", image {e.agent_image}" if e.agent_image else "")
        for e in manifest.environments
    )
    return [
        (
            "manifest",
            f"suite {manifest.suite} {manifest.suite_hash[:12]}, "
            f"{len(manifest.scenario_hashes)} scenarios, seeds {manifest.seeds_sha256[:12]}, "
            f"profile {manifest.profile} v{manifest.profile_version}, "
            f"model {_models_text(manifest)}",
        ),
        ("software", software or "-"),
    ]


def _models_text(manifest) -> str:
    """The trained model's sha256, or each training seed's."""
    if manifest.seed_models:
        return "; ".join(f"seed {m.seed} {m.model}" for m in manifest.seed_models)
    return manifest.model or "-"


def _interval_text(interval) -> str:
    return "" if interval is None else f" {interval_text(interval.low, interval.high)}"
