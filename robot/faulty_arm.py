"""Fault injection at the ``robot.Arm`` level, for soaks and tests on any rig.

``FaultyArm(inner, rate, seed)`` is an ``Arm`` that forwards to ``inner`` but raises
``InjectedBusError`` (a ``BusError``) on a seeded random fraction ``rate`` of reads and sends,
before the inner arm sees the call. The safety logic (clamping, step bound, watchdog, torque
off) stays in the ``Arm`` base class of the wrapper, exactly as for a real backend.
"""

from __future__ import annotations

import random

import numpy as np

from robot.arm import Arm, JointState
from robot.errors import BusError


class InjectedBusError(BusError):
    """A fault injected by ``FaultyArm``."""


class FaultyArm(Arm):
    """Wraps an arm; a fraction ``rate`` of ``_read``/``_send`` calls raise.

    Attributes:
        counts: faults injected per kind ('read', 'send') and calls per kind.
    """

    def __init__(self, inner: Arm, rate: float, seed: int = 0) -> None:
        if not 0.0 <= rate <= 1.0:
            raise ValueError(f"fault rate must be in [0, 1], got {rate}")
        super().__init__(inner.spec, inner.watchdog)
        self.inner = inner
        self.rate = rate
        self._rng = random.Random(seed)
        self.counts = {"read": 0, "send": 0, "read_calls": 0, "send_calls": 0}

    def _maybe_fail(self, kind: str) -> None:
        self.counts[f"{kind}_calls"] += 1
        if self.rate and self._rng.random() < self.rate:
            self.counts[kind] += 1
            raise InjectedBusError(f"injected {kind} fault")

    @property
    def position_resolution(self) -> np.ndarray:
        return self.inner.position_resolution

    def _connect(self) -> None:
        self.inner.connect()

    def _disconnect(self) -> None:
        self.inner.disconnect(torque_off=False)  # the wrapper already turned torque off

    def _read(self) -> JointState:
        self._maybe_fail("read")
        return self.inner._read()

    def _send(self, positions: np.ndarray) -> None:
        self._maybe_fail("send")
        self.inner._send(positions)

    def _set_torque(self, enabled: bool) -> None:
        self.inner._set_torque(enabled)

    def _initial_command(self) -> np.ndarray:
        return self.inner._initial_command()
