"""Errors the service functions raise; the API maps each to its HTTP status, the CLI prints it."""

from __future__ import annotations

from arena.errors import ArenaError


class ServiceError(ArenaError):
    status_code = 400

    def __init__(self, message: str) -> None:
        super().__init__(message)
        self.message = message


class NotFound(ServiceError):
    status_code = 404


class Conflict(ServiceError):
    """The request is valid but the object's state forbids it (cancel a scored submission)."""

    status_code = 409


class UploadTooLarge(ServiceError):
    status_code = 413


class InvalidInput(ServiceError):
    status_code = 422


class InvalidUpload(InvalidInput):
    """The upload or the zip inside it was rejected (the intake's message is passed through)."""


class QuotaExceeded(ServiceError):
    status_code = 429


class Forbidden(ServiceError):
    """The caller may not have this: a phase closed for uploads, agent output of a hidden phase."""

    status_code = 403
