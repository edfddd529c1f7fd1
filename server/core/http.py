"""uvicorn's HTTP/1.1 protocol with a deadline on request headers.

uvicorn bounds idle keep-alive connections (``timeout_keep_alive``) but not a client that sends
its request line and headers a byte at a time: 50 such connections were once held open for over
40 s each (slowloris). Here every connection must complete its request headers within
``ARENA_HTTP_HEADER_TIMEOUT_S`` of connecting (or of its previous response), or it is closed;
uvicorn builds the protocol per connection from what ``arena serve`` hands it (a partial with
``header_timeout_s``).
A request body (an upload) streams without this deadline: the receiving coroutine holds no
worker thread, and its size is capped (server/api/upload.py).
"""

from __future__ import annotations

import asyncio

import h11
from uvicorn.protocols.http.h11_impl import H11Protocol


class HeaderDeadlineProtocol(H11Protocol):
    def __init__(self, *args, header_timeout_s: float, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.header_timeout_s = header_timeout_s
        self._header_deadline: asyncio.TimerHandle | None = None

    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        super().connection_made(transport)
        self._arm_header_deadline()

    def connection_lost(self, exc: Exception | None) -> None:
        self._disarm_header_deadline()
        super().connection_lost(exc)

    def handle_events(self) -> None:
        super().handle_events()
        if self.conn.their_state is not h11.IDLE:
            self._disarm_header_deadline()  # the headers are in

    def on_response_complete(self) -> None:
        super().on_response_complete()
        if not self.transport.is_closing():
            self._arm_header_deadline()  # the next request on this connection, if any

    def _arm_header_deadline(self) -> None:
        self._disarm_header_deadline()
        self._header_deadline = self.loop.call_later(self.header_timeout_s, self._headers_late)

    def _disarm_header_deadline(self) -> None:
        if self._header_deadline is not None:
            self._header_deadline.cancel()
            self._header_deadline = None

    def _headers_late(self) -> None:
        self._header_deadline = None
        if self.conn.their_state is h11.IDLE and not self.transport.is_closing():
            self.transport.close()
