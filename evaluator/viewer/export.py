"""`arena replay`: find an episode's record and write it as a picture, a page or a video."""

from __future__ import annotations

from collections.abc import Callable
from enum import StrEnum
from pathlib import Path

from arena.record_format import RECORD_SUFFIX
from evaluator.runner.results import RECORDS_DIR, record_path
from evaluator.viewer.model import ReplayError, load_replay, scenario_folder


class ReplayFormat(StrEnum):
    svg = "svg"  # one still picture: the whole path coloured by speed
    html = "html"  # the replay page in one file, offline
    gif = "gif"
    mp4 = "mp4"


def find_record(path: Path, scenario_id: str | None) -> Path:
    """``path`` is a record, or a results folder of `arena evaluate` holding ``scenario_id``'s."""
    path = Path(path)
    if path.is_file():
        return path
    if not path.is_dir():
        raise ReplayError(f"{path}: no such record or results folder")
    if not (path / RECORDS_DIR).is_dir():
        raise ReplayError(f"{path}: not a results folder of `arena evaluate` (no {RECORDS_DIR}/)")
    if scenario_id is None:
        known = sorted(p.stem for p in (path / RECORDS_DIR).glob(f"*{RECORD_SUFFIX}"))
        if len(known) != 1:
            listed = ", ".join(known[:8]) + (" ..." if len(known) > 8 else "")
            raise ReplayError(f"{path}: name the scenario to replay (records: {listed})")
        scenario_id = known[0]
    record = record_path(path, scenario_id)
    if not record.exists():
        raise ReplayError(f"no record for {scenario_id} in {path}")
    return record


def write_replay(
    record: Path,
    suite_dir: Path | None,
    fmt: ReplayFormat,
    out: Path,
    *,
    every: int = 1,
    on_frames: Callable[[int], Callable[[], None]] = lambda _total: lambda: None,
) -> Path:
    """Write the episode of ``record`` as ``fmt``. Video formats draw every ``every``-th step;
    ``on_frames(total)`` returns what to call after each frame drawn (a progress bar)."""
    out = Path(out)
    if fmt is ReplayFormat.svg:
        # deferred: CLI start-up (the CLI imports this module); each format loads its renderer
        from evaluator.scoring.record import read_arrays, scalar
        from evaluator.viewer.picture import episode_svg

        arrays = read_arrays(record)
        folder = scenario_folder(suite_dir, str(scalar(arrays["scenario_id"])))
        out.write_text(episode_svg(arrays, folder))
        return out
    replay = load_replay(record, suite_dir)
    if fmt is ReplayFormat.html:
        # deferred: CLI start-up (the CLI imports this module); each format loads its renderer
        from evaluator.viewer.page import replay_html

        out.write_text(replay_html(replay))
        return out
    # deferred: CLI start-up (the CLI imports this module); each format loads its renderer
    from evaluator.viewer.frames import frame_count, frames, write_gif, write_mp4

    advance = on_frames(frame_count(replay, every))

    def drawn():
        for image in frames(replay, every):
            yield image
            advance()

    if fmt is ReplayFormat.gif:
        return write_gif(drawn(), out, frame_ms=round(replay.dt * every * 1000))
    return write_mp4(drawn(), out, fps=1.0 / (replay.dt * every))
