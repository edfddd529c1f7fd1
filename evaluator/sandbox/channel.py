"""The evaluator's end of the agent protocol (``docs/protocol.md``), with deadlines.

Frames are a 4-byte big-endian length and a payload. What we send is a pickle (protocol 5) of
``(kind, body)``; numpy arrays are pickled as ``numpy.ndarray(shape, dtype, buffer)`` so that any
numpy the runtime has can load them. The one exception is the binary act frame of
``observation_format: arrays`` (:mod:`evaluator.sandbox.array_frames`). What we receive is JSON
and is never unpickled: the agent is untrusted. Both descriptors are non-blocking and every wait
goes through ``poll`` with the time left, so a silent or stuck agent can never hold the evaluator
past its deadline.
"""

from __future__ import annotations

import io
import json
import os
import pickle
import select
import struct
import time
from typing import Any

import numpy as np

from arena.errors import ArenaError

HEADER = struct.Struct(">I")
# Replies carry a handful of actions; anything near this size is an agent writing garbage.
MAX_REPLY_BYTES = 16 * 1024**2
INBOX_BYTES = 64 * 1024
# A reply is an object holding a dict of short lists: nothing legitimate nests deeper. Checked on
# the raw bytes before parsing, since json's recursive decoder overflows the stack on a frame of
# a few thousand brackets.
MAX_REPLY_DEPTH = 32
# Replies are UTF-8 (docs/protocol.md): decoded as such, not sniffed for another encoding.
JSON = json.JSONDecoder()


class ChannelClosed(ArenaError):
    """The agent's end went away (it exited or was killed)."""


class ChannelTimeout(ArenaError):
    """The deadline passed before the whole frame moved."""


class ChannelViolation(ArenaError):
    """The agent sent something that is not a protocol frame."""


class ObservationPickler(pickle.Pickler):
    """Pickles numpy values in a form every numpy version loads."""

    def reducer_override(self, obj: Any) -> Any:
        if isinstance(obj, np.ndarray):
            if obj.dtype.hasobject:
                raise TypeError("observations may not hold object arrays")
            array = np.ascontiguousarray(obj)
            return np.ndarray, (array.shape, array.dtype.str, bytearray(array.tobytes()))
        if isinstance(obj, np.generic):
            value = obj.item()
            return type(value), (value,)
        return NotImplemented


class Channel:
    def __init__(self, read_fd: int, write_fd: int) -> None:
        self.read_fd = read_fd
        self.write_fd = write_fd
        os.set_blocking(read_fd, False)
        os.set_blocking(write_fd, False)
        self._readable = select.poll()
        self._readable.register(read_fd, select.POLLIN)
        self._writable = select.poll()
        self._writable.register(write_fd, select.POLLOUT)
        # Replies are read into one reused buffer: no allocation per step but the payload's.
        self._inbox = bytearray(INBOX_BYTES)
        self._filled = 0
        self._buffer = io.BytesIO()
        self._pickler = ObservationPickler(self._buffer, protocol=5)

    def send(self, kind: str, body: Any, deadline: float) -> None:
        """Write one message; ``deadline`` is a ``time.monotonic()`` value."""
        self._buffer.seek(0)
        self._buffer.truncate()
        self._pickler.clear_memo()
        self._pickler.dump((kind, body))
        payload = self._buffer.getbuffer()
        try:
            self.send_frame([payload], deadline)
        finally:
            del payload

    def send_frame(self, parts: list[bytes | bytearray | memoryview], deadline: float) -> None:
        """Write one frame whose payload is ``parts`` joined (written as they are, not copied)."""
        views = [memoryview(part).cast("B") for part in parts]
        size = sum(map(len, views))
        pending = [HEADER.pack(size), *views]
        left = HEADER.size + size
        try:
            while True:
                try:
                    written = os.writev(self.write_fd, pending)
                except BlockingIOError:
                    self._wait(self._writable, deadline)
                    continue
                except (BrokenPipeError, ConnectionResetError) as error:
                    raise ChannelClosed from error
                left -= written
                if not left:
                    return
                while written >= len(pending[0]):
                    written -= len(pending.pop(0))
                pending[0] = memoryview(pending[0])[written:]
        finally:
            del views, pending

    def receive(self, deadline: float) -> dict[str, Any]:
        """Read one message; ``deadline`` is a ``time.monotonic()`` value."""
        while True:
            if self._filled >= HEADER.size:
                (size,) = HEADER.unpack_from(self._inbox)
                if size > MAX_REPLY_BYTES:
                    raise ChannelViolation(f"a reply of {size} bytes (limit {MAX_REPLY_BYTES})")
                end = HEADER.size + size
                if end > len(self._inbox):
                    self._inbox.extend(bytes(end - len(self._inbox)))
                if self._filled >= end:
                    payload = self._inbox[HEADER.size : end]
                    left = self._filled - end
                    if left:
                        self._inbox[:left] = self._inbox[end : self._filled]
                    self._filled = left
                    return decode_reply(payload)
            self._wait(self._readable, deadline)
            try:
                received = os.readv(self.read_fd, [memoryview(self._inbox)[self._filled :]])
            except BlockingIOError:
                continue
            except ConnectionResetError as error:
                raise ChannelClosed from error
            if not received:
                raise ChannelClosed
            self._filled += received

    @staticmethod
    def _wait(poller: select.poll, deadline: float) -> None:
        left = deadline - time.monotonic()
        if left <= 0 or not poller.poll(left * 1000):
            raise ChannelTimeout


_STRUCTURAL = b'[]{}"\\'
_NOT_STRUCTURAL = bytes(b for b in range(256) if b not in _STRUCTURAL)


def exceeds_depth(payload: bytes | bytearray, limit: int) -> bool:
    """Whether a JSON text nests brackets deeper than ``limit`` (brackets in strings ignored)."""
    if payload.count(b"[") + payload.count(b"{") <= limit:
        return False
    depth = 0
    in_string = escaped = False
    # Only brackets, quotes and backslashes matter: drop the rest before the byte loop.
    for byte in payload.translate(None, _NOT_STRUCTURAL):
        if in_string:
            if escaped:
                escaped = False
            elif byte == 0x5C:  # backslash
                escaped = True
            elif byte == 0x22:  # quote
                in_string = False
        elif byte == 0x22:
            in_string = True
        elif byte in (0x5B, 0x7B):  # [ {
            depth += 1
            if depth > limit:
                return True
        else:
            depth -= 1
    return False


def decode_reply(payload: bytes | bytearray) -> dict[str, Any]:
    """The agent's JSON message. Every way a payload can be bad is a :class:`ChannelViolation`
    (the agent's ``agent_error``), never an exception of ours."""
    if exceeds_depth(payload, MAX_REPLY_DEPTH):
        raise ChannelViolation(f"a reply nested more than {MAX_REPLY_DEPTH} deep")
    try:
        message = JSON.decode(payload.decode())
    except (UnicodeDecodeError, ValueError, RecursionError) as error:
        # ValueError covers JSONDecodeError and an integer of more than 4300 digits.
        raise ChannelViolation(f"a reply that is not JSON: {error}"[:300]) from error
    if not isinstance(message, dict) or not isinstance(message.get("type"), str):
        raise ChannelViolation("a reply without a message type")
    return message
