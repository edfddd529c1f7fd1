"""``scores.json``: the scores of a results folder's episodes, kept beside its summary so that a
resumed evaluation does not re-read every record. Re-reading costs about 10 ms a record: 36 s
before the first new episode of a resumed Driving SMARTS 2022 run (3,607 episodes).

A score is reused only under the scoring profile it was computed with (the profile's whole
content, not its name) and for its record as it was then (size and modification time): anything
else is scored from the record again. Floats are written as JSON reprs, so a reused score is the
same number, bit for bit, and so is every summary made from it.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from pathlib import Path

from arena.files import write_atomically
from evaluator.scoring import EpisodeScore, ScoringProfile

SCORES_FILE = "scores.json"


class ScoreCache:
    """The cache of the results folder ``out_dir`` under ``profile``."""

    def __init__(self, out_dir: Path, profile: ScoringProfile) -> None:
        self.path = Path(out_dir) / SCORES_FILE
        self.profile = hashlib.sha256(profile.model_dump_json().encode()).hexdigest()
        # name -> (score, its record's stamp): a finished record does not change, so it is
        # stamped once, not at every write; an episode run again brings a new score object.
        self._stamped: dict[str, tuple[EpisodeScore, list[int] | None]] = {}

    def load(self, records: dict[str, Path | None]) -> dict[str, EpisodeScore]:
        """The stored scores of the episodes named in ``records`` (name -> its record, None
        when it has none) that are still valid."""
        try:
            stored = json.loads(self.path.read_text())
        except (OSError, ValueError):
            return {}  # none yet, or cut short: every episode is scored again
        if not isinstance(stored, dict) or stored.get("profile") != self.profile:
            return {}
        valid = {}
        for name, item in stored.get("episodes", {}).items():
            stamp = item.get("record")
            if name in records and stamp == _stamp(records[name]):
                try:
                    valid[name] = EpisodeScore(**item["score"])
                except (TypeError, KeyError):
                    continue
                self._stamped[name] = (valid[name], stamp)
        return valid

    def write(self, scores: dict[str, tuple[EpisodeScore, Path | None]]) -> None:
        """Store ``scores`` (episode name -> its score and its record), replacing the file."""
        for name, (score, record) in scores.items():
            known = self._stamped.get(name)
            if known is None or known[0] is not score:
                self._stamped[name] = (score, _stamp(record))
        episodes = {
            name: {"record": self._stamped[name][1], "score": dataclasses.asdict(score)}
            for name, (score, _) in scores.items()
        }
        text = json.dumps({"profile": self.profile, "episodes": episodes}, separators=(",", ":"))
        write_atomically(self.path, text)


def _stamp(record: Path | None) -> list[int] | None:
    """What says a record is the one a score was computed from: its size and mtime [ns]."""
    if record is None:
        return None
    try:
        stat = record.stat()
    except OSError:
        return [-1, -1]  # gone: matches no stored stamp
    return [stat.st_size, stat.st_mtime_ns]
