"""The runtime's framed stream: a read takes whatever has arrived, so frames that come together,
in pieces, or bigger than its buffer each come out whole and in order."""

from __future__ import annotations

import os
import pickle
import socket
import threading

import pytest

from agent_runtime.main import HEADER, Closed, Stream


def framed(payload: bytes) -> bytes:
    return HEADER.pack(len(payload)) + payload


def message(kind: str, body: object) -> bytes:
    return framed(pickle.dumps((kind, body), protocol=5))


@pytest.fixture
def ends():
    ours, theirs = socket.socketpair()
    yield Stream(ours.fileno(), ours.fileno()), theirs
    ours.close()
    theirs.close()


def test_frames_sent_together_come_out_one_by_one(ends) -> None:
    stream, evaluator = ends
    arrays = framed(b"a" + bytes(range(100)))
    evaluator.sendall(message("layout", {"size": 8}) + arrays + message("reset", None))
    assert stream.receive() == ("layout", {"size": 8})
    kind, payload = stream.receive()
    assert kind == "arrays" and bytes(payload) == b"a" + bytes(range(100))
    assert stream.receive() == ("reset", None)


def test_a_frame_in_pieces_and_one_bigger_than_the_buffer(ends) -> None:
    stream, evaluator = ends
    small = message("act", {"Agent_0": [1.0]})
    big = message("act", {"Agent_0": os.urandom(3 * len(stream.buffer))})
    data = small + big + small

    def trickle() -> None:  # split inside a header and inside each payload
        for at in range(0, len(data), 7919):
            evaluator.sendall(data[at : at + 7919])

    sender = threading.Thread(target=trickle)
    sender.start()
    try:
        received = [stream.receive() for _ in range(3)]
    finally:
        sender.join()
    assert received == [pickle.loads(small[4:]), pickle.loads(big[4:]), pickle.loads(small[4:])]


def test_the_stream_ending_mid_frame_is_closed(ends) -> None:
    stream, evaluator = ends
    evaluator.sendall(message("reset", None)[:-3])
    evaluator.shutdown(socket.SHUT_WR)
    with pytest.raises(Closed):
        stream.receive()
