"""The leaderboards: each team's best scored submission per phase and track, ranked by the
scoring spec.

The ordering rule lives in :func:`evaluator.scoring.rank` (lexicographic on the four errors, full
ties to the earlier submission), the rank ranges and the statistical ties they define in
:mod:`evaluator.scoring.significance`; this module only chooses the candidates and caches the
result (and each score's bootstrap replicates, which never change while the score stands).
"""

from __future__ import annotations

import io
import math
import threading
import time
from dataclasses import dataclass
from datetime import datetime

import numpy as np
from sqlalchemy import or_, select
from sqlalchemy.orm import Session

from arena.figures import METRICS
from arena.neutralise.spreadsheet import write_rows
from evaluator.scoring import Metrics as ScoringMetrics
from evaluator.scoring import MetricSamples, rank
from evaluator.scoring.significance import RankRange, ranges_from_replicates, replicates
from server.core.db import Database
from server.models import (
    EvaluationRun,
    LeaderboardGeneration,
    Score,
    SeedSetScore,
    Submission,
    Team,
    Track,
    TrainingJob,
)
from server.schemas import (
    FamilyMetrics,
    GeneralisationGap,
    Leaderboard,
    LeaderboardEntry,
    Metrics,
)
from server.services.phases import DEFAULT_PHASE, get_phase, list_phases
from server.services.seed_sets import seed_results
from server.services.submissions import completion_interval
from server.status import RunStatus, SubmissionStatus

# A score's bootstrap replicates (None: scored before per-episode values were kept), by its
# table, id and when it was computed (a re-score writes a new row).
Replicates = dict[tuple[str, int, datetime], "np.ndarray | None"]
Standing = Score | SeedSetScore  # a run's score, or a seed set's over several seeds


def _key(score: Standing) -> tuple[str, int, datetime]:
    return (score.__tablename__, score.id, score.computed_at)


def _replicates(session: Session, scores: list[Standing], known: Replicates) -> list:
    """Each score's replicates, from ``known`` or resampled from its stored samples; ``known``
    is left holding exactly these scores' (a replaced score's drop out)."""
    used = {_key(s) for s in scores}
    for key in [key for key in known if key not in used]:
        del known[key]
    for table in (Score, SeedSetScore):
        missing = [s.id for s in scores if isinstance(s, table) and _key(s) not in known]
        if not missing:
            continue
        query = select(table.id, table.samples).where(table.id.in_(missing))
        stored = {score_id: samples for score_id, samples in session.execute(query)}
        for score in scores:
            if isinstance(score, table) and score.id in stored:
                samples = stored[score.id]
                known[_key(score)] = (
                    None if samples is None else replicates(MetricSamples.from_json(samples))
                )
    return [known[_key(s)] for s in scores]


def compute(
    session: Session,
    track: Track,
    phase: str = DEFAULT_PHASE,
    known: Replicates | None = None,
) -> Leaderboard:
    """The board; ``known`` keeps scores' bootstrap replicates between calls."""
    shown = (
        Submission.phase == phase,
        Submission.track == track,
        Submission.status == SubmissionStatus.scored,
    )
    runs = session.execute(
        select(
            Submission, Team.name, EvaluationRun.attempt, Score, EvaluationRun.episodes_per_scenario
        )
        .join(Team, Team.id == Submission.team_id)
        .join(EvaluationRun, EvaluationRun.submission_id == Submission.id)
        .join(Score, Score.run_id == EvaluationRun.id)
        .outerjoin(TrainingJob, TrainingJob.id == EvaluationRun.training_id)
        .where(
            *shown,
            EvaluationRun.status == RunStatus.scored,
            # A seed of several is scored with its set, never alone.
            or_(TrainingJob.id.is_(None), TrainingJob.seeds == 1),
        )
    ).all()
    seed_sets = session.execute(
        select(
            Submission,
            Team.name,
            SeedSetScore.attempt,
            SeedSetScore,
            SeedSetScore.episodes_per_scenario,
        )
        .join(Team, Team.id == Submission.team_id)
        .join(SeedSetScore, SeedSetScore.submission_id == Submission.id)
        .where(*shown)
    ).all()
    rows = [*runs, *seed_sets]
    # A submission's standing score is that of its latest scored attempt (or seed set).
    latest: dict[int, tuple] = {}
    for row in rows:
        submission, _, attempt = row[:3]
        if submission.id not in latest or attempt > latest[submission.id][2]:
            latest[submission.id] = tuple(row)

    def metrics(row: tuple) -> ScoringMetrics:
        score = row[3]
        return ScoringMetrics(**{name: getattr(score, name) for name in METRICS})

    def submitted_at(row: tuple) -> tuple:
        return (row[0].created_at, row[0].id)

    best_per_team: dict[str, tuple] = {}
    for row in rank(latest.values(), metrics=metrics, submitted_at=submitted_at):
        best_per_team.setdefault(row[1], row)
    intervals = [completion_interval(row[3]) for row in best_per_team.values()]
    scores = [row[3] for row in best_per_team.values()]
    ranges = ranges_from_replicates(_replicates(session, scores, {} if known is None else known))
    entries = [
        LeaderboardEntry(
            rank=position,
            team=team,
            submission_id=submission.id,
            method_name=submission.method_name,
            submitted_at=submission.created_at,
            metrics=Metrics.model_validate(score),
            completion_interval=interval,
            tied_with=list(ranks.tied_with),
            rank_low=ranks.low,
            rank_high=ranks.high,
            rank_range=ranks.label,
            beats_next=ranks.beats_next,
            compared=ranks.compared,
            episodes_per_scenario=episodes,
            seeds=seed_results(score),
            families={
                family: FamilyMetrics.model_validate(values)
                for family, values in score.families.items()
            },
        )
        for position, ((submission, team, _, score, episodes), interval, ranks) in enumerate(
            zip(best_per_team.values(), intervals, ranges, strict=True), start=1
        )
    ]
    return Leaderboard(phase=phase, track=track, entries=entries)


def rank_range(entry: LeaderboardEntry) -> RankRange:
    """The entry's rank range, to say it in words (:attr:`RankRange.statement`)."""
    return RankRange(
        entry.rank, entry.rank_low, entry.rank_high, entry.beats_next, compared=entry.compared
    )


def with_gap(board: Leaderboard, reference: Leaderboard) -> Leaderboard:
    """``board`` with each entry's generalisation gap: its metrics minus those of its team's
    entry on ``reference`` (another phase's board of the same track; overfitting to a public
    suite shows as a positive gap on the hidden one)."""
    theirs = {entry.team: entry for entry in reference.entries}

    def gap(entry: LeaderboardEntry) -> GeneralisationGap | None:
        other = theirs.get(entry.team)
        if other is None:
            return None
        difference = {
            name: None
            if getattr(entry.metrics, name) is None or getattr(other.metrics, name) is None
            else getattr(entry.metrics, name) - getattr(other.metrics, name)
            for name in METRICS
        }
        return GeneralisationGap(
            phase=reference.phase,
            submission_id=other.submission_id,
            metrics=other.metrics,
            difference=Metrics(**difference),
        )

    return board.model_copy(
        update={
            "gap_from": reference.phase,
            "entries": [e.model_copy(update={"gap": gap(e)}) for e in board.entries],
        }
    )


def generation(session: Session) -> int:
    return (
        session.scalar(select(LeaderboardGeneration.value).where(LeaderboardGeneration.id == 1))
        or 0
    )


def _csv_value(value: float | None) -> str:
    return "" if value is None else repr(value)


def _gap(entry: LeaderboardEntry, name: str) -> float | None:
    return None if entry.gap is None else getattr(entry.gap.difference, name)


def to_csv(board: Leaderboard) -> str:
    """The board as CSV; every cell through :mod:`arena.neutralise.spreadsheet` (a method name
    ``=HYPERLINK(...)`` stays text in whatever spreadsheet opens it)."""
    out = io.StringIO()
    header = [
        "rank",
        "rank_range",
        "beats_next",
        "team",
        "submission_id",
        "method_name",
        "submitted_at",
        *METRICS,
        "completion_low",
        "completion_high",
        "tied_with",
        "seeds",
        "seed_completion_min",
        "seed_completion_max",
        "seed_completion_std",
        *([f"gap_{name}" for name in METRICS] if board.gap_from else []),
    ]
    rows = (
        [
            entry.rank,
            entry.rank_range,
            _csv_value(entry.beats_next),
            entry.team,
            entry.submission_id,
            entry.method_name,
            entry.submitted_at.isoformat(),
            *(_csv_value(getattr(entry.metrics, name)) for name in METRICS),
            *(
                _csv_value(getattr(entry.completion_interval, bound, None))
                for bound in ("low", "high")
            ),
            " ".join(str(rank) for rank in entry.tied_with),
            entry.seeds.count if entry.seeds is not None else 1,
            *(
                _csv_value(getattr(entry.seeds, f"completion_{name}", None))
                for name in ("min", "max", "std")
            ),
            *([_csv_value(_gap(entry, name)) for name in METRICS] if board.gap_from else []),
        ]
        for entry in board.entries
    )
    write_rows(out, header, rows)
    return out.getvalue()


@dataclass
class _Cached:
    generation: int
    checked_at: float  # time.monotonic() [s]
    board: Leaderboard
    json: bytes


class LeaderboardCache:
    """Computed leaderboards per phase and track, kept until the generation counter changes.

    Workers in other processes bump the counter when they write a score; this process looks at it
    at most every ``recheck_s`` seconds, so a new score shows within that delay and a burst of
    requests costs no database work at all. While one request recomputes a board, the others are
    served the board it replaces (only the very first computation of a board is waited for).
    Each board has its own lock: computing one never holds up a request for another.
    """

    def __init__(self, db: Database, recheck_s: float = 1.0) -> None:
        self.db = db
        self.recheck_s = recheck_s
        self._cached: dict[tuple[str, Track], _Cached] = {}
        self._replicates: dict[tuple[str, Track], Replicates] = {}
        self._locks: dict[tuple[str, Track], threading.Lock] = {}

    def _lock(self, key: tuple[str, Track]) -> threading.Lock:
        return self._locks.setdefault(key, threading.Lock())  # atomic: one lock per board

    def fresh(self, track: Track, phase: str = DEFAULT_PHASE) -> _Cached | None:
        """The cached board if it needs no database look (cheap enough for the event loop)."""
        cached = self._cached.get((phase, track))
        if cached is not None and time.monotonic() - cached.checked_at < self.recheck_s:
            return cached
        return None

    def get(self, track: Track, phase: str = DEFAULT_PHASE) -> _Cached:
        cached = self.fresh(track, phase)
        if cached is not None:
            return cached
        key = (phase, track)
        moment = time.monotonic()
        stale = self._cached.get(key)
        lock = self._lock(key)
        if not lock.acquire(blocking=stale is None):
            # Another request is re-ranking (a new score resamples its entry): the board it
            # replaces is served meanwhile, so a burst never queues behind the computation.
            return stale
        try:
            cached = self._cached.get(key)
            if cached is not None and cached.checked_at >= moment:
                # Checked while this request waited for the lock: nothing older is served.
                return cached
            with self.db.read_session() as session:
                get_phase(session, phase)  # an unknown phase is a 404, never cached
                current = generation(session)
                if cached is None or cached.generation != current:
                    cached = self._compute(session, key, current, moment)
                else:
                    cached.checked_at = moment
            self._cached[key] = cached
            return cached
        finally:
            lock.release()

    def _compute(
        self, session: Session, key: tuple[str, Track], current: int, moment: float
    ) -> _Cached:
        phase, track = key
        board = compute(session, track, phase, self._replicates.setdefault(key, {}))
        return _Cached(current, moment, board, board.model_dump_json().encode())

    def warm(self) -> None:
        """Compute every board no request has asked for yet, so that the first request after a
        start finds the bootstrap replicates made (seconds for a few hundred entries). A warmed
        board counts as never checked: its first request still looks at the generation, so a
        score written meanwhile shows at once."""
        with self.db.read_session() as session:
            keys = [(phase.name, track) for phase in list_phases(session) for track in Track]
        for key in keys:
            with self._lock(key):
                if key in self._cached:
                    continue  # a request came first
                with self.db.read_session() as session:
                    self._cached[key] = self._compute(session, key, generation(session), -math.inf)
