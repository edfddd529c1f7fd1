"""What an admin command acts on, built when the command first needs it: the settings, the
database (refused with what to do when it is missing or not migrated), the task queue and the
artifact store; and the service's refusals turned into one error line."""

from __future__ import annotations

from collections.abc import Callable
from typing import Annotated, TypeVar

import typer

from server.commands.console import fail

# The API's bound (server.api.deps.MAX_ROW_ID): a larger id is a usage error, not a driver's
# overflow traceback.
MAX_ID = 2**31 - 1
SubmissionId = Annotated[int, typer.Argument(help="Submission id.", min=1, max=MAX_ID)]
# The same, where other options can stand in for it (`rescore --all`, `audit --sample N`).
OptionalSubmissionId = Annotated[
    int | None, typer.Argument(help="Submission id.", min=1, max=MAX_ID)
]

T = TypeVar("T")


class AdminContext:
    """Settings, database, task queue and artifact store of the configured service."""

    def __init__(self) -> None:
        # deferred: CLI start-up time
        from arena.config import get_settings
        from server.core.artifacts import artifact_store
        from server.core.db import Database
        from server.core.migrate import DatabaseNotReady, check_database_ready
        from server.core.queue import TaskQueue

        self.settings = get_settings()
        try:
            check_database_ready(self.settings.storage.resolved_database_url)
        except DatabaseNotReady as exc:
            raise fail(exc) from None
        self.db = Database(self.settings.storage.resolved_database_url)
        self.queue = TaskQueue(self.settings)
        self.store = artifact_store(self.settings.storage, self.db)


def or_fail(action: Callable[[], T]) -> T:
    """``action()``, or exit with its refusal (a service error, an illegal status change)."""
    # deferred: CLI start-up time
    from server.services.errors import ServiceError
    from server.status import IllegalTransition

    try:
        return action()
    except (ServiceError, IllegalTransition) as exc:
        raise fail(exc) from None
