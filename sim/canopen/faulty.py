"""A canopen network that loses a fraction of PDO/SYNC frames, both ways: the emulated drives'
side of a lossy bus (``sim.canopen.drives``). Its ``heartbeats``, when set, produce the nodes'
heartbeats instead of python-can's periodic tasks (``sim.canopen.heartbeats``)."""

from __future__ import annotations

import random
import threading
from collections.abc import Callable
from typing import Any

import canopen

SYNC_COB_ID = 0x080


def _is_pdo_or_sync(can_id: int) -> bool:
    """SYNC and the four TPDO/RPDO pairs (0x180..0x57F), not SDO/EMCY/NMT/heartbeat."""
    return can_id == SYNC_COB_ID or 0x180 <= can_id < 0x580


class FaultyNetwork(canopen.Network):
    """A canopen network that loses a fraction of PDO/SYNC frames, both ways."""

    # Longest blocking receive of the notifier thread, s (bounds the time ``stop`` takes).
    NOTIFIER_CYCLE = 0.1

    def __init__(self, bus: Any, drop_rate: float, seed: int) -> None:
        super().__init__(bus)
        self.drop_rate = drop_rate
        self.dropped = 0
        self._rng = random.Random(seed)
        self._rng_lock = threading.Lock()
        #: (node id, data, period s) -> a task with ``update(data)`` and ``stop()``: who produces
        #: the heartbeats (None: python-can's periodic tasks on the bus)
        self.heartbeats: Callable[[int, bytes, float], Any] | None = None

    def _drop(self, can_id: int) -> bool:
        if self.drop_rate <= 0 or not _is_pdo_or_sync(can_id):
            return False
        with self._rng_lock:
            lost = self._rng.random() < self.drop_rate
        if lost:
            self.dropped += 1
        return lost

    def notify(self, can_id: int, data: bytearray, timestamp: float) -> None:
        if not self._drop(can_id):
            super().notify(can_id, data, timestamp)

    def send_message(self, can_id: int, data: bytes, remote: bool = False) -> None:
        if not self._drop(can_id):
            super().send_message(can_id, data, remote)

    def send_periodic(self, can_id: int, data: bytes, period: float, remote: bool = False) -> Any:
        """A heartbeat (0x701..0x77F) to ``heartbeats`` when set; anything else as usual."""
        node = can_id - 0x700
        if self.heartbeats is not None and 1 <= node <= 127 and not remote:
            return self.heartbeats(node, bytes(data), period)
        return super().send_periodic(can_id, data, period, remote)
