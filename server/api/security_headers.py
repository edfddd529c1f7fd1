"""Security headers on every response, and the nonce that lets our own inline scripts run.

- ``Content-Security-Policy``: scripts only from this origin or carrying the response's nonce (so
  an injected ``<script>`` never runs), no plugins, no framing, no ``<base>`` rewrites, forms post
  only here. Styles may be inline (the chart and Swagger UI set them); nothing else loads from
  another origin.
- ``X-Frame-Options: DENY`` (older browsers' framing guard), ``X-Content-Type-Options: nosniff``
  (a zip or a log is never run as a script), ``Referrer-Policy: same-origin``.

Pages put ``request.state.csp_nonce`` on each inline ``<script>``. Asset URLs are paths (under the
configured ``ARENA_PUBLIC_BASE_URL``, if any), never built from the request's ``Host`` header.
"""

from __future__ import annotations

import secrets

from fastapi.templating import Jinja2Templates
from jinja2 import pass_context
from starlette.types import ASGIApp, Message, Receive, Scope, Send

NONCE_BYTES = 16


def content_security_policy(nonce: str) -> str:
    return "; ".join(
        [
            "default-src 'self'",
            f"script-src 'self' 'nonce-{nonce}'",
            "style-src 'self' 'unsafe-inline'",
            "img-src 'self' data: blob:",
            "object-src 'none'",
            "base-uri 'none'",
            "frame-ancestors 'none'",
            "form-action 'self'",
        ]
    )


class SecurityHeaders:
    """Pure ASGI middleware (no buffering of streamed bodies)."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        nonce = secrets.token_urlsafe(NONCE_BYTES)
        scope.setdefault("state", {})["csp_nonce"] = nonce
        headers = [
            (b"content-security-policy", content_security_policy(nonce).encode()),
            (b"x-frame-options", b"DENY"),
            (b"x-content-type-options", b"nosniff"),
            (b"referrer-policy", b"same-origin"),
        ]

        async def send_with_headers(message: Message) -> None:
            if message["type"] == "http.response.start":
                names = {name.lower() for name, _ in message.get("headers", [])}
                message["headers"] = [
                    *message.get("headers", []),
                    *((name, value) for name, value in headers if name not in names),
                ]
            await send(message)

        await self.app(scope, receive, send_with_headers)


def with_nonce(html: str, nonce: str) -> str:
    """Our own page's inline scripts (one we did not template, e.g. Swagger UI's), allowed."""
    return html.replace("<script>", f'<script nonce="{nonce}">')


@pass_context
def asset(context, mount: str, path: str) -> str:
    """The URL of a static file: a path under the configured base URL, never from ``Host``."""
    request = context["request"]
    base = request.app.state.settings.service.public_base_url
    return base + str(request.app.url_path_for(mount, path=path))


def page_templates(directory) -> Jinja2Templates:
    """The Jinja environment of our pages: autoescaped, with :func:`asset`."""
    templates = Jinja2Templates(directory=directory)
    templates.env.globals["asset"] = asset
    return templates
