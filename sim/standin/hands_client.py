"""The client of the stand-in's hands (``sim.standin.hands.HandsServer``): one JSON line a
request on 127.0.0.1, as ``ergo twin serve`` prints its port (``hands on 127.0.0.1:PORT``)."""

from __future__ import annotations

import json
import socket
from collections.abc import Mapping, Sequence
from typing import Any

from sim.standin.hands import HOST, MOVE_WALL_BOUND_S, HandsError


class HandsClient:
    """The hands' client: each method sends one request and returns the reply's fields, or
    raises ``HandsError`` with the server's one-line reason.

    Args:
        port: the port ``ergo twin serve`` printed (``hands on 127.0.0.1:PORT``).
        host: 127.0.0.1 (the hands listen nowhere else).
        timeout: seconds to wait for a reply (a move waits until the joints are there).
    """

    def __init__(self, port: int, host: str = HOST, timeout: float = MOVE_WALL_BOUND_S + 10):
        try:
            self._sock = socket.create_connection((host, int(port)), timeout=timeout)
        except OSError as exc:
            raise HandsError(f"no hands on {host}:{port}: {exc}") from None
        self._file = self._sock.makefile("rwb")

    def request(self, cmd: str, **fields: Any) -> dict[str, Any]:
        """Send ``{"cmd": cmd, **fields}``; the reply (``ok`` true) or ``HandsError``."""
        self._file.write((json.dumps({"cmd": cmd, **fields}) + "\n").encode())
        self._file.flush()
        line = self._file.readline()
        if not line:
            raise HandsError("the hands closed the connection")
        reply = json.loads(line)
        if not reply.get("ok"):
            raise HandsError(reply.get("error", "the hands refused"))
        return reply

    def move(self, joints: Mapping[str, float], speed: float | None = None) -> dict[str, Any]:
        """Move limp joints (name -> true joint angle, rad) there and hold them; ``speed``:
        the hand's, rad/s (None: the server's careful person)."""
        fields: dict[str, Any] = {"joints": {k: float(v) for k, v in joints.items()}}
        if speed is not None:
            fields["speed"] = float(speed)
        return self.request("move", **fields)

    def release(self, joints: Sequence[str] | None = None) -> dict[str, Any]:
        """Let go of the named joints (None: all)."""
        return self.request("release", **({} if joints is None else {"joints": list(joints)}))

    def show_board(
        self,
        board: Mapping[str, Any],
        position: Sequence[float],
        euler_deg: Sequence[float] = (0.0, 0.0, 0.0),
    ) -> dict[str, Any]:
        """Hold a board (its geometry: ``sim.standin.board.BoardGeometry.from_dict``) at a
        pose (``board_to_world``)."""
        return self.request(
            "board",
            board=dict(board),
            position=[float(v) for v in position],
            euler_deg=[float(v) for v in euler_deg],
        )

    def put_board_away(self) -> dict[str, Any]:
        return self.request("board_away")

    def place_ball(self, position: Sequence[float]) -> dict[str, Any]:
        """Put the ball down at rest at ``position`` (x, y) m, inside the wall."""
        return self.request("ball", position=[float(v) for v in position])

    def status(self) -> dict[str, Any]:
        """What the hands hold, and what they did on their own since the last status."""
        return self.request("status")

    def close(self) -> None:
        try:
            self._file.close()
        finally:
            self._sock.close()

    def __enter__(self) -> HandsClient:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
