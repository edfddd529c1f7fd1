"""What the OpenAPI document promises beyond the handlers' signatures: the error body every
status code answers with, which codes each router answers, and the upload's multipart form (the
handler streams the body itself, so FastAPI cannot infer it; with it, ``/docs`` can upload)."""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel, ConfigDict

from server.api.upload import FILE_FIELD, MAX_FIELD_BYTES
from server.models import Track


class ErrorBody(BaseModel):
    """Every error answer. ``detail`` is a message, or for a request that fails validation
    FastAPI's list of ``{loc, msg, type}`` problems."""

    model_config = ConfigDict(frozen=True)

    detail: str | list[dict[str, Any]]


DESCRIPTIONS = {
    400: "The JSON body could not be parsed",
    401: "No bearer token, or an unknown or revoked one",
    403: "Not allowed: a phase closed for uploads, agent output of a hidden phase, or no admin "
    "token configured",
    404: "No such object (or it belongs to another team)",
    409: "The object's state forbids the action",
    413: "The upload exceeds the size or form limits",
    422: "A parameter, form field or the zip broke a rule; the message names it",
    429: "The team's daily quota for the track is used up",
    503: "The database or the broker is unreachable",
}


def errors(*codes: int) -> dict[int | str, dict[str, Any]]:
    """``responses=`` for a route or router answering ``codes`` with :class:`ErrorBody`."""
    return {code: {"model": ErrorBody, "description": DESCRIPTIONS[code]} for code in codes}


UPLOAD_FORM: dict[str, Any] = {
    "requestBody": {
        "required": True,
        "content": {
            "multipart/form-data": {
                "schema": {
                    "type": "object",
                    "required": [FILE_FIELD, "method_name"],
                    "properties": {
                        FILE_FIELD: {
                            "type": "string",
                            "format": "binary",
                            "description": "The submission zip (see docs/submissions.md)",
                        },
                        "phase": {
                            "type": "string",
                            "default": "final",
                            "maxLength": 32,
                            "description": "The competition phase (docs/deployment.md)",
                        },
                        "track": {
                            "type": "string",
                            "enum": [t.value for t in Track],
                            "default": Track.freestyle.value,
                        },
                        "method_name": {"type": "string", "minLength": 1, "maxLength": 128},
                        "description": {"type": "string", "maxLength": MAX_FIELD_BYTES},
                    },
                }
            }
        },
    }
}


def allowed_methods(app: Any, path: str) -> list[str]:
    """Every method some route of ``app`` answers at ``path``. Starlette's 405 lists only the
    methods of the first route whose path matched (``Allow: POST`` for ``/submissions``, which
    also answers GET)."""
    methods: set[str] = set()
    for route in app.routes:
        regex = getattr(route, "path_regex", None)
        if regex is not None and regex.match(path):
            methods |= set(getattr(route, "methods", None) or ())
    if "GET" in methods:
        methods.add("HEAD")
    return sorted(methods)
