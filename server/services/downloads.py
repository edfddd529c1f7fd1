"""The per-submission download: everything its own team may see, in one zip.

``submission.json`` (status, scores, per-family metrics, failure counts, phase and standing: the
detail the API returns), ``upload/agent.zip`` (the zip the team uploaded, byte for byte) and, in
a phase of full visibility only, ``logs.json`` and one ``logs/<family>-<k>.txt`` per finished
scenario. In a hidden phase nothing the agent wrote and no per-scenario detail is in it.
"""

from __future__ import annotations

import io
import re
import zipfile

from sqlalchemy.orm import Session

from arena.config import SandboxSettings, ServiceSettings
from server.core.artifacts import ArtifactStore, MissingArtifact
from server.models import Submission
from server.services import phases, standing, submissions

UPLOAD_ENTRY = "upload/agent.zip"

# Fixed entry dates: the same results give the same bytes.
_DATE = (2000, 1, 1, 0, 0, 0)


def _entry(archive: zipfile.ZipFile, name: str, text: str) -> None:
    info = zipfile.ZipInfo(name, date_time=_DATE)
    info.compress_type = zipfile.ZIP_DEFLATED
    archive.writestr(info, text)


def log_file_name(label: str) -> str:
    """``"cruise #2"`` -> ``"logs/cruise-2.txt"``."""
    return "logs/" + re.sub(r"[^A-Za-z0-9_.-]+", "-", label.replace(" #", "-")) + ".txt"


def download_name(submission: Submission) -> str:
    return f"submission-{submission.id}.zip"


def submission_zip(
    session: Session,
    service: ServiceSettings,
    sandbox: SandboxSettings,
    store: ArtifactStore,
    submission: Submission,
) -> bytes:
    detail = standing.team_view(session, service, sandbox, submission)
    visible = phases.team_sees_everything(phases.get_phase(session, submission.phase))
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w") as archive:
        _entry(archive, "submission.json", detail.model_dump_json(indent=2))
        try:
            uploaded = store.read(submission.upload_key)
        except MissingArtifact:  # deleted by an organiser: the rest is still the team's
            uploaded = None
        if uploaded is not None:
            info = zipfile.ZipInfo(UPLOAD_ENTRY, date_time=_DATE)
            archive.writestr(info, uploaded)  # stored: a zip does not deflate again
        if not visible:
            return _closed(buffer, archive)
        logs = submissions.logs(session, submission)
        _entry(archive, "logs.json", logs.model_dump_json(indent=2))
        for entry in logs.scenarios:
            header = f"# {entry.label}: {entry.reason or entry.status}\n"
            _entry(archive, log_file_name(entry.label), header + (entry.log_tail or ""))
    return buffer.getvalue()


def _closed(buffer: io.BytesIO, archive: zipfile.ZipFile) -> bytes:
    archive.close()
    return buffer.getvalue()
