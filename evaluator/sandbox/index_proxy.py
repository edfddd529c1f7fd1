"""The resolver sandbox's only way out: an HTTP proxy on a unix socket that reaches the configured
package index's hosts and nothing else.

The sandbox has no network of its own (a namespace with loopback only); its relay
(``agent_runtime/resolve.py``) forwards pip's proxied connections to this socket, mounted into
it. Each connection carries one request: ``CONNECT <host>:<port>`` (HTTPS: a tunnel, pip checks
the certificate end to end) or a plain ``GET http://<host>:<port>/...`` (a local index), allowed
only when ``<host>:<port>`` is one of the index's. Anything else gets ``403`` and the connection
is closed.
"""

from __future__ import annotations

import contextlib
import socket
import threading
from collections.abc import Iterable
from pathlib import Path
from urllib.parse import urlsplit

from agent_runtime.resolve import pump

MAX_HEAD_BYTES = 64 * 1024
CONNECT_TIMEOUT_S = 30.0
DEFAULT_PORTS = {"http": 80, "https": 443}


def allowed_address(url: str) -> tuple[str, int] | None:
    """``(host, port)`` of an http(s) URL; None for anything else (a folder, ``file:``)."""
    parts = urlsplit(url)
    if parts.scheme not in DEFAULT_PORTS or not parts.hostname:
        return None
    return parts.hostname.lower(), parts.port or DEFAULT_PORTS[parts.scheme]


class IndexProxy:
    """Listens on ``socket_path`` until :meth:`close`, relaying to ``allowed`` addresses only."""

    def __init__(self, socket_path: Path, allowed: Iterable[tuple[str, int]]) -> None:
        self.allowed = frozenset(allowed)
        self.socket_path = socket_path
        self.refused: list[str] = []  # what the sandbox asked for and did not get
        self._listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        self._listener.bind(str(socket_path))
        self._listener.listen(32)
        self._closed = threading.Event()
        self._thread = threading.Thread(target=self._serve, name="index-proxy", daemon=True)
        self._thread.start()

    def close(self) -> None:
        self._closed.set()
        with contextlib.suppress(OSError):
            self._listener.shutdown(socket.SHUT_RDWR)
        self._listener.close()
        self._thread.join(timeout=5)
        self.socket_path.unlink(missing_ok=True)

    def __enter__(self) -> IndexProxy:
        return self

    def __exit__(self, *_: object) -> None:
        self.close()

    def _serve(self) -> None:
        while not self._closed.is_set():
            try:
                client, _ = self._listener.accept()
            except OSError:
                return
            threading.Thread(target=self._handle, args=(client,), daemon=True).start()

    def _handle(self, client: socket.socket) -> None:
        with client:
            head = _read_head(client)
            if head is None:
                return
            request_line, _, rest = head.partition(b"\r\n")
            try:
                method, target, version = request_line.decode("ascii").split(" ")
            except (UnicodeDecodeError, ValueError):
                return _refuse(client, 400)
            if method == "CONNECT":
                host, _, port = target.rpartition(":")
                address = (host.strip("[]").lower(), int(port)) if port.isdigit() else None
                forward = b""
            else:
                address = allowed_address(target)
                path = urlsplit(target)._replace(scheme="", netloc="").geturl() or "/"
                # One request per connection: its successor might name another host.
                headers = [
                    line
                    for line in rest.split(b"\r\n")
                    if line and not line.lower().startswith((b"connection:", b"proxy-"))
                ]
                forward = b"\r\n".join(
                    [f"{method} {path} {version}".encode(), *headers, b"Connection: close"]
                )
                forward += b"\r\n\r\n"
            if address not in self.allowed:
                self.refused.append(target[:200])
                return _refuse(client, 403)
            try:
                upstream = socket.create_connection(address, timeout=CONNECT_TIMEOUT_S)
            except OSError:
                return _refuse(client, 502)
            with upstream:
                upstream.settimeout(None)
                if method == "CONNECT":
                    client.sendall(b"HTTP/1.1 200 Connection established\r\n\r\n")
                else:
                    upstream.sendall(forward)
                sending = threading.Thread(target=pump, args=(client, upstream), daemon=True)
                sending.start()
                pump(upstream, client)
                sending.join(timeout=CONNECT_TIMEOUT_S)


def _read_head(client: socket.socket) -> bytes | None:
    data = b""
    while b"\r\n\r\n" not in data:
        chunk = client.recv(4096)
        if not chunk or len(data) + len(chunk) > MAX_HEAD_BYTES:
            return None
        data += chunk
    head, _, body = data.partition(b"\r\n\r\n")
    # A proxied GET has no body; a CONNECT's tunnel starts after the reply.
    return head if not body else None


def _refuse(client: socket.socket, status: int) -> None:
    with contextlib.suppress(OSError):
        client.sendall(f"HTTP/1.1 {status} Refused\r\nContent-Length: 0\r\n\r\n".encode())
