"""A 150 MiB upload against a real uvicorn process: refused, and the server's memory does not
grow by anything like the upload's size."""

from __future__ import annotations

import httpx
import pytest

from tests.server.builders import bearer, make_team
from tests.server.live import api_server, peak_rss_bytes

UPLOAD_BYTES = 150 * 2**20
CHUNK = b"\0" * 2**20


def streamed_body(boundary: str):
    """A multipart body produced chunk by chunk with no Content-Length (chunked encoding)."""
    yield (
        f'--{boundary}\r\nContent-Disposition: form-data; name="method_name"\r\n\r\nbig\r\n'
        f'--{boundary}\r\nContent-Disposition: form-data; name="file"; filename="a.zip"\r\n'
        "Content-Type: application/zip\r\n\r\n"
    ).encode()
    for _ in range(UPLOAD_BYTES // len(CHUNK)):
        yield CHUNK
    yield f"\r\n--{boundary}--\r\n".encode()


@pytest.mark.slow
def test_150_mib_upload_is_refused_without_filling_memory(settings, db, tmp_path):
    _, token = make_team(db, "alpha")
    with api_server(settings, tmp_path / "api.log") as (url, process):
        before = peak_rss_bytes(process.pid)
        boundary = "arena-boundary"
        try:
            response = httpx.post(
                f"{url}/api/v1/submissions",
                headers={
                    **bearer(token),
                    "Content-Type": f"multipart/form-data; boundary={boundary}",
                },
                content=streamed_body(boundary),
                timeout=120,
            )
            assert response.status_code == 413
            assert "exceeds the limit" in response.json()["detail"]
        except (httpx.WriteError, httpx.RemoteProtocolError, httpx.ReadError):
            pass  # the server answered and closed the connection while we were still sending
        growth = peak_rss_bytes(process.pid) - before
        assert growth < 40 * 2**20, f"server memory grew by {growth / 2**20:.0f} MiB"
        # Nothing of the refused upload is left on disk, and nothing was recorded.
        uploads = settings.storage.resolved_data_dir / "uploads"
        assert not any(uploads.iterdir()) if uploads.exists() else True
        assert httpx.get(f"{url}/api/v1/submissions", headers=bearer(token)).json() == []


def many_fields_body(boundary: str, fields: int, size: int):
    """8,000 form fields of almost 64 KiB each: under the per-field limit, 500 MiB in all."""
    value = b"v" * size
    for i in range(fields):
        yield (
            f'--{boundary}\r\nContent-Disposition: form-data; name="f{i}"\r\n\r\n'.encode()
            + value
            + b"\r\n"
        )
    yield f"--{boundary}--\r\n".encode()


@pytest.mark.slow
def test_8000_form_fields_are_refused_without_filling_memory(settings, db, tmp_path):
    """Fields were capped only one by one: 8,000 of them pushed the API from 115 to 588 MiB."""
    _, token = make_team(db, "alpha")
    with api_server(settings, tmp_path / "api.log") as (url, process):
        before = peak_rss_bytes(process.pid)
        boundary = "arena-boundary"
        try:
            response = httpx.post(
                f"{url}/api/v1/submissions",
                headers={
                    **bearer(token),
                    "Content-Type": f"multipart/form-data; boundary={boundary}",
                },
                content=many_fields_body(boundary, 8000, 60_000),
                timeout=120,
            )
            assert response.status_code == 413
            assert "fields" in response.json()["detail"]
        except (httpx.WriteError, httpx.RemoteProtocolError, httpx.ReadError):
            pass  # the server answered and closed the connection while we were still sending
        growth = peak_rss_bytes(process.pid) - before
        assert growth < 40 * 2**20, f"server memory grew by {growth / 2**20:.0f} MiB"
        assert httpx.get(f"{url}/api/v1/healthz").status_code == 200
