"""What makes a table a job of the engine: :class:`LeasedJob`, the columns every job row carries
(an episode's ``scenario_results``, ``training_jobs``, ``upload_validations``), which
:mod:`server.jobs.leases` claims, fences, renews and reaps the same way for every kind."""

from __future__ import annotations

from datetime import datetime

from sqlalchemy import ColumnElement, Integer, String
from sqlalchemy.orm import Mapped, mapped_column


class LeasedJob:
    """A job's row: who holds it, under which claim, until when. A table mixes it in and says,
    with a hybrid property ``under_way``, when its job is still to be written by its holder
    (e.g. ``status == running``): both a Python test on a row and an SQL condition."""

    # The worker holding the job ("host:pid"); empty when nobody does (never claimed yet,
    # released, reaped or finished).
    worker: Mapped[str] = mapped_column(String(255), default="")
    # Claims so far (1 for the first; more after workers died holding it or handed it back):
    # the fence token every write of the job's result goes through.
    claim_number: Mapped[int] = mapped_column(Integer, default=0)
    # Until when the holder's lease runs (its heartbeat renews it). Set when the job's task is
    # sent, too: the reaper re-sends a job nobody took by then.
    lease_expires_at: Mapped[datetime | None]

    under_way: bool | ColumnElement[bool]
