"""Releasing a closed phase: its suite becomes downloadable and every team may watch its own
episodes of it. Until the organisers release it, nothing changes (a phase that has not closed
cannot be released)."""

from __future__ import annotations

import os
import zipfile
from datetime import datetime
from pathlib import Path

from sqlalchemy import select

from arena.config import SuiteSettings
from arena.suite import load_suite
from server.core.db import Database
from server.models import Phase, utcnow
from server.services.errors import Conflict, Forbidden
from server.services.phases import get_phase, suite_dir

# Fixed entry dates: the same suite gives the same bytes.
_DATE = (2000, 1, 1, 0, 0, 0)


def release_phase(db: Database, name: str, moment: datetime | None = None) -> Phase:
    """Release the closed phase ``name`` (again: no change)."""
    moment = moment or utcnow()
    with db.session() as session:
        get_phase(session, name)  # an unknown phase: NotFound, naming the known ones
        phase = session.scalar(select(Phase).where(Phase.name == name).with_for_update())
        if phase.released_at is None:
            if phase.ends_at is None or phase.ends_at > moment:
                closes = (
                    f"closes at {phase.ends_at:%Y-%m-%d %H:%M} UTC"
                    if phase.ends_at
                    else "has no end date"
                )
                raise Conflict(
                    f"phase {name!r} {closes}: release it once it has closed "
                    "(arena admin phases set NAME --ends T)"
                )
            phase.released_at = moment
        session.flush()
        session.expunge(phase)
        return phase


def released_suite(session, suites: SuiteSettings, data_dir: Path, name: str) -> Path:
    """The zip of a released phase's suite (made once, then served as a file); Forbidden before
    the release."""
    phase = get_phase(session, name)
    if phase.released_at is None:
        raise Forbidden(
            f"the suite of phase {name!r} is not released: the organisers release it after the "
            "phase closes"
        )
    suite = load_suite(suite_dir(phase, suites, data_dir))
    folder = data_dir / "released"
    path = folder / f"{phase.name}-{suite.sha256[:16]}.zip"
    if not path.exists():
        folder.mkdir(parents=True, exist_ok=True)
        partial = path.with_suffix(f".{os.getpid()}.part")
        with zipfile.ZipFile(partial, "w", zipfile.ZIP_DEFLATED) as archive:
            for file in sorted(p for p in suite.root.rglob("*") if p.is_file()):
                info = zipfile.ZipInfo(file.relative_to(suite.root).as_posix(), date_time=_DATE)
                info.compress_type = zipfile.ZIP_DEFLATED
                archive.writestr(info, file.read_bytes())
        os.replace(partial, path)  # a concurrent request never serves half a zip
    return path
