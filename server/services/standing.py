"""Where a team stands: its submission's phase (dates, what is hidden), its place on the
leaderboard and the uploads it has left today. Shown on the submission page, in the API's
detail and in the download, so a team never has to guess."""

from __future__ import annotations

from datetime import datetime

from sqlalchemy.orm import Session

from arena.config import SandboxSettings, ServiceSettings
from server.models import Phase, Submission, Team, utcnow
from server.schemas import (
    Allowance,
    CpuLimitsView,
    PhaseWindow,
    Standing,
    SubmissionDetail,
    TeamStatus,
)
from server.services import leaderboard, phases, submissions
from server.tracks import Track


def phase_window(session: Session, sandbox: SandboxSettings, name: str) -> PhaseWindow:
    return _window(phases.get_phase(session, name), sandbox)


def _window(phase, sandbox: SandboxSettings) -> PhaseWindow:
    limits = phases.cpu_limits(phase, sandbox)
    return PhaseWindow(
        name=phase.name,
        visibility=str(phase.visibility),
        starts_at=phase.starts_at,
        ends_at=phase.ends_at,
        state=phases.state(phase, utcnow()),
        hidden=phases.what_is_hidden(phase),
        cpu_limits=CpuLimitsView(
            step_s=limits.step_s, episode_s=limits.episode_s, evaluation_s=limits.evaluation_s
        ),
    )


def standing(session: Session, service: ServiceSettings, submission: Submission) -> Standing:
    phase = phases.get_phase(session, submission.phase)
    board = leaderboard.compute(session, submission.track, submission.phase)
    ours = next((e for e in board.entries if e.team == submission.team.name), None)
    quota = phases.daily_quota(phase, service)
    return Standing(
        rank=ours.rank if ours else None,
        teams_ranked=len(board.entries),
        ranked_submission_id=ours.submission_id if ours else None,
        rank_low=ours.rank_low if ours else None,
        rank_high=ours.rank_high if ours else None,
        rank_range=ours.rank_range if ours else None,
        beats_next=ours.beats_next if ours else None,
        compared=ours.compared if ours else True,
        tied_with=ours.tied_with if ours else [],
        statistics=leaderboard.rank_range(ours).statement if ours else "",
        tries_left_today=tries_left_today(
            session, service, submission.team_id, phase, submission.track, utcnow()
        ),
        daily_quota=quota,
    )


def tries_left_today(
    session: Session,
    service: ServiceSettings,
    team_id: int,
    phase: Phase,
    track: Track,
    moment: datetime,
) -> int:
    """Uploads the team may still make in the phase and track today: none while the phase is
    not open (the one count the submission page, its standing and ``GET /team`` show)."""
    if not phases.is_open(phase, moment):
        return 0
    used = submissions.quota_used(session, team_id, phase.name, track, moment)
    return max(0, phases.daily_quota(phase, service) - used)


def team_view(
    session: Session, service: ServiceSettings, sandbox: SandboxSettings, submission: Submission
) -> SubmissionDetail:
    """The detail its team sees, with the phase and where the team stands."""
    return submissions.detail(session, submission).model_copy(
        update={
            "phase_window": phase_window(session, sandbox, submission.phase),
            "standing": standing(session, service, submission),
        }
    )


def team_status(
    session: Session, service: ServiceSettings, sandbox: SandboxSettings, team: Team
) -> TeamStatus:
    """Uploads left today in every phase and track (0 where a phase is not open)."""
    moment = utcnow()
    allowances = []
    for phase in phases.list_phases(session):
        quota = phases.daily_quota(phase, service)
        for track in Track:
            allowances.append(
                Allowance(
                    phase=_window(phase, sandbox),
                    track=track,
                    tries_left_today=tries_left_today(
                        session, service, team.id, phase, track, moment
                    ),
                    daily_quota=quota,
                )
            )
    return TeamStatus(team=team.name, allowances=allowances)
