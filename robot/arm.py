"""The ``Arm`` interface every backend implements (twin, Dynamixel serial, CANopen).

The base class owns the safety logic so that no backend can skip it:
- ``command`` clamps to the joint limits and to the maximum step from the last command sent;
- ``read`` feeds the watchdog (temperature, load) which turns torque off when a limit holds;
- ``disconnect`` (and leaving the ``with`` block, on exception too) turns torque off.

Units: positions rad, velocities rad/s, loads as a signed fraction of the maximum torque,
temperatures degrees C, timestamps seconds (``time.monotonic`` or the twin's clock).
"""

from __future__ import annotations

import logging
from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np

from robot.errors import NotConnectedError, SafetyStop
from robot.safety import Watchdog
from robot.spec import ArmSpec

log = logging.getLogger(__name__)


@dataclass
class JointState:
    """One reading of all joints.

    Attributes:
        positions: shape (n,), rad.
        velocities: shape (n,), rad/s.
        loads: shape (n,), signed fraction of the maximum torque (NaN if unknown).
        temperatures: shape (n,), degrees C (NaN if unknown).
        errors: shape (n,), backend error flags per joint, 0 when healthy.
        timestamp: seconds.
    """

    positions: np.ndarray
    velocities: np.ndarray
    loads: np.ndarray
    temperatures: np.ndarray
    errors: np.ndarray
    timestamp: float

    @classmethod
    def from_positions(
        cls, positions: np.ndarray, timestamp: float, **kw: np.ndarray
    ) -> JointState:
        """A state with only positions known (others zero or NaN unless given)."""
        n = len(positions)
        nan = np.full(n, np.nan)
        return cls(
            positions=np.asarray(positions, dtype=float),
            velocities=kw.get("velocities", np.zeros(n)),
            loads=kw.get("loads", nan.copy()),
            temperatures=kw.get("temperatures", nan.copy()),
            errors=kw.get("errors", np.zeros(n, dtype=int)),
            timestamp=timestamp,
        )


class Arm(ABC):
    """Abstract arm: a context manager that connects on entry and turns torque off on exit."""

    def __init__(self, spec: ArmSpec, watchdog: Watchdog | None = None) -> None:
        self.spec = spec
        self.watchdog = watchdog if watchdog is not None else Watchdog()
        self._connected = False
        self._torque = False
        self._last_sent: np.ndarray | None = None
        self._resync_needed = False

    # ---- lifecycle -------------------------------------------------------------------------
    @property
    def is_connected(self) -> bool:
        return self._connected

    @property
    def torque_enabled(self) -> bool:
        return self._torque

    @property
    def last_sent(self) -> np.ndarray | None:
        """The last command actually sent, shape (n,), rad (None before the first)."""
        return None if self._last_sent is None else self._last_sent.copy()

    def connect(self) -> None:
        """Open the link and read the joints once; torque stays as the backend found it."""
        if self._connected:
            return
        self._connect()
        self._connected = True
        self.resync()

    def resync(self) -> None:
        """Re-seed the step bound from the arm itself (after connect, or after the backend's
        state was restored): the next command moves at most ``max_step`` from here."""
        self._require()
        self._last_sent = np.asarray(self._initial_command(), dtype=float).copy()
        self._resync_needed = False

    def _initial_command(self) -> np.ndarray:
        """Where the step bound starts from: the measured positions by default, shape (n,)."""
        return self._read().positions

    def disconnect(self, torque_off: bool = True) -> None:
        """Close the link, turning torque off first unless told otherwise. Never raises."""
        if not self._connected:
            return
        try:
            if torque_off:
                self.set_torque(False)
        except Exception as exc:  # keep going: the link must still be closed
            log.error("could not turn torque off on disconnect: %s", exc)
        finally:
            try:
                self._disconnect()
            except Exception as exc:
                log.error("error while closing %s: %s", type(self).__name__, exc)
            finally:
                self._connected = False

    def __enter__(self) -> Arm:
        self.connect()
        return self

    def __exit__(self, *exc: object) -> None:
        self.disconnect(torque_off=True)

    # ---- I/O -------------------------------------------------------------------------------
    def read(self) -> JointState:
        """Read all joints; the watchdog may stop the arm (``SafetyStop``, torque off)."""
        self._require()
        state = self._read()
        reason = self.watchdog.check(state)
        if reason is not None:
            self._emergency_torque_off()
            raise SafetyStop(reason)
        return state

    def command(self, positions: np.ndarray) -> np.ndarray:
        """Send goal positions after clamping; returns what was sent, shape (n,), rad."""
        self._require()
        if self._resync_needed:
            # the previous send failed: it may or may not have reached the servos, so the
            # step bound restarts from where the arm really is
            self.resync()
        safe = self.spec.clamp(positions, self._last_sent)
        try:
            self._send(safe)
        except Exception:
            self._resync_needed = True
            raise
        self._last_sent = safe
        return safe.copy()

    def set_torque(self, enabled: bool) -> None:
        """Enable or disable torque on every joint.

        Enabling first sets the goal to the measured positions, so a limp arm moved by hand
        does not jump back to its last command.
        """
        self._require()
        if enabled:
            here = self.spec.clamp(self._read().positions, None)
            self._send(here)
            self._last_sent = here
        self._set_torque(enabled)
        self._torque = enabled

    def _emergency_torque_off(self) -> None:
        try:
            self._set_torque(False)
        except Exception as exc:
            log.error("emergency torque off failed: %s", exc)
        self._torque = False

    def _require(self) -> None:
        if not self._connected:
            raise NotConnectedError(f"{type(self).__name__} is not connected: call connect() first")

    # ---- backend hooks ---------------------------------------------------------------------
    @abstractmethod
    def _connect(self) -> None: ...

    @abstractmethod
    def _disconnect(self) -> None: ...

    @abstractmethod
    def _read(self) -> JointState: ...

    @abstractmethod
    def _send(self, positions: np.ndarray) -> None:
        """Write goal positions (already clamped), shape (n,), rad."""

    @abstractmethod
    def _set_torque(self, enabled: bool) -> None: ...
