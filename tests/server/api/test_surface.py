"""The service's surface toward any client: security headers on every response, no URL built from
the Host header, and slow clients that cannot hold the server (issue 23)."""

from __future__ import annotations

import contextlib
import re
import socket
import time

import httpx
import pytest

from tests.server.builders import bearer, make_team, pack_example
from tests.server.live import api_server
from tests.settings import with_fields

PAGES = (
    "/",
    "/submit",
    "/scenarios",
    "/guide/submissions",
    "/docs",
    "/api/v1/leaderboard",
    "/api/v1/openapi.json",
    "/static/app.js",
    "/api/v1/no-such-route",
)


@pytest.mark.parametrize("path", PAGES)
def test_every_response_carries_the_security_headers(client, db, path):
    response = client.get(path)
    headers = response.headers
    assert headers["x-frame-options"] == "DENY"
    assert headers["x-content-type-options"] == "nosniff"
    assert headers["referrer-policy"] == "same-origin"
    policy = headers["content-security-policy"]
    assert "default-src 'self'" in policy and "frame-ancestors 'none'" in policy
    assert re.search(r"script-src 'self' 'nonce-[A-Za-z0-9_-]+'", policy)
    assert "unsafe-inline" not in policy.split("script-src", 1)[1].split(";", 1)[0]


@pytest.mark.parametrize("path", ["/", "/submit", "/docs", "/my-submissions"])
def test_inline_scripts_carry_the_nonce_of_their_response(client, db, path):
    response = client.get(path)
    nonce = re.search(r"'nonce-([^']+)'", response.headers["content-security-policy"]).group(1)
    scripts = re.findall(r"<script([^>]*)>", response.text)
    assert scripts
    for attributes in scripts:
        assert "src=" in attributes or f'nonce="{nonce}"' in attributes, attributes
    assert (
        client.get(path).headers["content-security-policy"]
        != response.headers["content-security-policy"]
    )  # a nonce per response


@pytest.mark.parametrize("path", ["/", "/submit", "/scenarios", "/my-submissions", "/docs"])
def test_no_url_is_built_from_the_host_header(client, db, path):
    page = client.get(path, headers={"Host": "attacker.invalid"})
    assert "attacker.invalid" not in page.text
    assert '/static/style.css"' in page.text or path == "/docs"


def test_the_upload_location_is_a_path(client, db, tmp_path):
    _, token = make_team(db, "alpha")
    response = client.post(
        "/api/v1/submissions",
        headers={**bearer(token), "Host": "attacker.invalid"},
        data={"method_name": "keep lane"},
        files={"file": ("a.zip", pack_example("keep_lane", tmp_path).read_bytes())},
    )
    assert response.status_code == 202
    assert response.headers["location"].startswith("/api/v1/submissions/")


@pytest.mark.slow  # a live API process
def test_slow_clients_are_cut_off_and_do_not_hold_the_server(settings, db, tmp_path):
    """50 connections trickling their headers once held the API for 40 s and more."""
    slow = with_fields(settings, service={"http_header_timeout_s": 1.0})
    with api_server(slow, tmp_path / "api.log") as (url, _):
        port = int(url.rsplit(":", 1)[1])
        sockets = []
        for _ in range(50):
            connection = socket.create_connection(("127.0.0.1", port))
            connection.sendall(b"GET /api/v1/leaderboard HTTP/1.1\r\nHost: x\r\n")  # never ends
            sockets.append(connection)
        started = time.monotonic()
        assert httpx.get(f"{url}/api/v1/leaderboard", timeout=5).status_code == 200
        closed = 0
        for connection in sockets:
            connection.settimeout(max(0.1, 5 - (time.monotonic() - started)))
            with contextlib.suppress(TimeoutError):  # still open: counted as not closed
                closed += connection.recv(1) == b""
            connection.close()
        assert closed == 50
        assert time.monotonic() - started < 5
