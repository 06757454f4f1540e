"""The twin's servers hold every connection their accepting thread has not taken yet.

With socketserver's default listen queue (5), a client connecting while the accepting thread
waited for the GIL had its SYN dropped and got its connection ~1.03 s later (TCP's first
retransmission). Here the accepting thread is stopped outright (``shutdown`` ends
``serve_forever`` and leaves the socket listening): 60 clients in a row must each connect at
once, as they would while the thread is merely late.
"""

from __future__ import annotations

import socket
import time

import numpy as np
import pytest

from sim.loopback import HOST, LISTEN_BACKLOG
from sim.mjpeg_server import MjpegServer
from sim.standin.hands import HandsServer

CLIENTS = 60  # as the probe that found the 1.03 s connections: 60 in a row
CONNECT_S = 0.5  # a dropped SYN waits 1 s for its retransmission; a held one connects at once


class _IdleHands:
    """What HandsServer needs of the hands, doing nothing."""

    def start(self) -> None:
        pass

    def stop(self) -> None:
        pass

    def handle(self, request: dict) -> dict:
        return {"ok": True}


def _connect_while_nobody_accepts(server, listener) -> list[float]:
    listener.shutdown()  # the accepting loop ends; the socket keeps listening
    times, held = [], []
    try:
        for _ in range(CLIENTS):
            start = time.monotonic()
            held.append(socket.create_connection((HOST, server.port), timeout=CONNECT_S))
            times.append(time.monotonic() - start)
    finally:
        for s in held:
            s.close()
    return times


@pytest.mark.parametrize("kind", ["mjpeg", "hands"])
def test_sixty_clients_connect_at_once_while_the_server_accepts_none(kind):
    assert CLIENTS < LISTEN_BACKLOG
    if kind == "mjpeg":
        server = MjpegServer(lambda: np.zeros((8, 8, 3), np.uint8), fps=1.0)
    else:
        server = HandsServer(_IdleHands())  # type: ignore[arg-type]
    server.start()
    try:
        listener = server._httpd if kind == "mjpeg" else server._server
        times = _connect_while_nobody_accepts(server, listener)
    finally:
        server.stop()
    assert len(times) == CLIENTS
    assert max(times) < CONNECT_S, times
