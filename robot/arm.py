"""The ``Arm`` interface every backend implements (twin, Dynamixel serial, CANopen).

The base class owns the safety logic so that no backend can skip it:
- ``command`` clamps to the joint limits and to the maximum step from the last command sent;
- ``read`` feeds the watchdog (temperature, load) which turns torque off when a limit holds;
- ``disconnect`` (and leaving the ``with`` block, on exception too) turns torque off;
- a lost link (``LinkLost``: adapter unplugged, port closed) during ``read``/``command`` is
  recovered in place when the backend can reconnect: at most ``RecoveryPolicy.attempts``
  reconnections with a growing pause, then the positions are read back, torque is re-enabled
  holding the measured pose (if it was on) and the call is retried once; otherwise a
  ``SafetyStop`` (torque off where the servos can still be reached) ends the run, which can be
  resumed from its folder. ``fault_counts()`` gives the counters (links lost, reconnections,
  time spent recovering, and the backend's bus counters).

Units: positions rad, velocities rad/s, loads as a signed fraction of the maximum torque,
temperatures degrees C, timestamps seconds (``time.monotonic`` or the twin's clock).
"""

from __future__ import annotations

import logging
import threading
import time
from abc import ABC, abstractmethod
from dataclasses import asdict, dataclass

import numpy as np

from robot.errors import BusError, LinkLost, NotConnectedError, SafetyStop
from robot.joint_state import JointState
from robot.spec import ArmSpec
from robot.torque_guardian import EmergencyPayload
from robot.watchdog import Watchdog

log = logging.getLogger(__name__)


# Reconnection attempts after a lost link before a safe stop, and the pauses between them:
# 0.1, 0.2, 0.4, 0.8, 1.0 s (3.5 s in all, plus the attempts). Guesses: a USB-serial adapter
# that was re-plugged re-enumerates within about a second; five tries ride that out without
# leaving a run hanging for long.
DEFAULT_RECONNECT_ATTEMPTS = 5
DEFAULT_RECONNECT_FIRST_DELAY_S = 0.1
DEFAULT_RECONNECT_MAX_DELAY_S = 1.0


@dataclass(frozen=True)
class RecoveryPolicy:
    """How an arm recovers from a lost link.

    Attributes:
        attempts: reconnections tried before giving up (0: never reconnect, stop at once).
        first_delay_s: pause before the first attempt, doubled after each failure, s.
        max_delay_s: longest pause between two attempts, s.
    """

    attempts: int = DEFAULT_RECONNECT_ATTEMPTS
    first_delay_s: float = DEFAULT_RECONNECT_FIRST_DELAY_S
    max_delay_s: float = DEFAULT_RECONNECT_MAX_DELAY_S

    def __post_init__(self) -> None:
        if self.attempts < 0 or self.first_delay_s < 0 or self.max_delay_s < 0:
            raise ValueError(f"recovery policy needs non-negative values, got {self}")

    def delays(self) -> list[float]:
        """The pause before each attempt, s."""
        return [min(self.first_delay_s * 2**k, self.max_delay_s) for k in range(self.attempts)]


@dataclass
class ArmCounters:
    """Link faults of one arm since it was created.

    Attributes:
        links_lost: times a ``LinkLost`` reached the arm during ``read``/``command``.
        reconnects: recoveries that brought the arm back (the call then went through).
        reconnect_attempts: reconnections tried, successful or not.
        recovery_s: wall time spent recovering, successful or not, s.
        stops_after_link_loss: recoveries that gave up (``SafetyStop`` raised).
    """

    links_lost: int = 0
    reconnects: int = 0
    reconnect_attempts: int = 0
    recovery_s: float = 0.0
    stops_after_link_loss: int = 0


class Arm(ABC):
    """Abstract arm: a context manager that connects on entry and turns torque off on exit.

    Args:
        spec: joints, limits and step bound.
        watchdog: load/temperature watchdog (default thresholds if None).
        recovery: what to do when the link is lost (default ``RecoveryPolicy()``; only used
            when the backend ``can_reconnect``).
    """

    def __init__(
        self,
        spec: ArmSpec,
        watchdog: Watchdog | None = None,
        recovery: RecoveryPolicy | None = None,
    ) -> None:
        self.spec = spec
        self.watchdog = watchdog if watchdog is not None else Watchdog()
        self.recovery = recovery if recovery is not None else RecoveryPolicy()
        self.counters = ArmCounters()
        self._connected = False
        self._torque = False
        self._last_sent: np.ndarray | None = None
        self._resync_needed = False
        # set by ``interrupt`` (a signal): no recovery may turn torque back on
        self._interrupted = threading.Event()
        # when the last ``interrupt`` began, and when the last torque-off command left the host
        # (the write to the port returned, the frames went to the adapter): time.monotonic s,
        # None before. What a test of the torque-off latency needs to tell the host's share
        # from the servos' (or an emulator's).
        self.interrupted_at: float | None = None
        self.torque_off_sent_at: float | None = None
        #: what the servos do when this process dies without its own torque-off (SIGKILL, an
        #: OOM kill): "limp" (the default: a guardian process, and on CANopen the drives'
        #: heartbeat consumer, cut torque) or "hold" (they keep their last target; the user's
        #: explicit choice, the rigs' option ``on_crash``). Set it before ``connect``.
        self.on_crash = "limp"
        #: a backend's word on its last torque-off when it could not confirm it (CANopen:
        #: "not confirmed by ...: sent to ..."), None when confirmed or not said
        self.torque_off_report: str | None = None
        #: True while a disconnect that ends in an exception turns torque off: a backend then
        #: leaves its report in ``torque_off_report`` instead of logging it (the exception
        #: carries it, ``disconnect``)
        self.quiet_torque_off = False

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
        self._interrupted.clear()
        self._connect()
        self._connected = True
        self.resync()

    @property
    def position_resolution(self) -> np.ndarray:
        """Smallest change a position reading can show, per joint, shape (n,), rad: one raw
        unit of the servo or drive, 0 where readings are continuous (the twin's own arm)."""
        return np.zeros(self.spec.n)

    @property
    def can_reconnect(self) -> bool:
        """Whether ``_reconnect`` can reopen the link after a ``LinkLost`` (backends that open
        their port by name say yes)."""
        return False

    def fault_counts(self) -> dict[str, float]:
        """Counters of faults and recoveries: ``ArmCounters`` plus the backend's own (bus
        retries, timeouts, CRC errors, late cycles...), by name. For a run's metrics."""
        out: dict[str, float] = dict(asdict(self.counters))
        out["recovery_s"] = round(out["recovery_s"], 3)
        out.update(self._backend_counts())
        return out

    def _backend_counts(self) -> dict[str, float]:
        """The backend's own counters (none by default)."""
        return {}

    def resync(self) -> None:
        """Re-seed the step bound from the arm itself (after connect, or after the backend's
        state was restored): the next command moves at most ``max_step`` from here."""
        self._require()
        self._last_sent = np.asarray(self._initial_command(), dtype=float).copy()
        self._resync_needed = False

    def _initial_command(self) -> np.ndarray:
        """Where the step bound starts from: the measured positions by default, shape (n,)."""
        return self._read().positions

    def disconnect(self, torque_off: bool = True, during: BaseException | None = None) -> None:
        """Close the link, turning torque off first unless told otherwise. Never raises.

        ``during``: the exception that ends the arm's use, if any (``__exit__`` passes it).
        A torque-off that then fails or is not confirmed is added to it as a note
        (``BaseException.add_note``), which the command's one ``ergo: error:`` line prints
        after the cause (``plumbing.cli_errors.error``), instead of a log line of its own
        beside it: the same link loss is said once, with what it left undone."""
        if not self._connected:
            return
        try:
            if torque_off:
                self.quiet_torque_off = during is not None
                try:
                    self.set_torque(False)
                finally:
                    self.quiet_torque_off = False
                report = self.torque_off_report
                if during is not None and report and report not in str(during):
                    during.add_note(f"torque off {report}")  # unless its stop said it
        except Exception as exc:  # keep going: the link must still be closed
            if during is not None:
                during.add_note(f"could not turn torque off on disconnect: {exc}")
                log.debug("could not turn torque off on disconnect: %s", exc)
            else:
                log.error("could not turn torque off on disconnect: %s", exc)
        finally:
            try:
                self._disconnect()
            except Exception as exc:
                log.error("error while closing %s: %s", type(self).__name__, exc)
            finally:
                self._connected = False
                self._log_counts()

    def _log_counts(self) -> None:
        """One line of fault counters at disconnect (a warning when the link was lost)."""
        try:
            counts = self.fault_counts()
        except Exception:  # counters must never break a disconnect
            return
        level = logging.WARNING if counts.get("links_lost") else logging.INFO
        text = ", ".join(f"{k} {v}" for k, v in counts.items() if v)
        log.log(level, "%s fault counters: %s", type(self).__name__, text or "none")

    def __enter__(self) -> Arm:
        self.connect()
        return self

    def __exit__(self, exc_type: object, exc: BaseException | None, tb: object) -> None:
        self.disconnect(torque_off=True, during=exc)

    # ---- I/O -------------------------------------------------------------------------------
    def read(self) -> JointState:
        """Read all joints; the watchdog may stop the arm (``SafetyStop``, torque off). A lost
        link is recovered first when the backend can reconnect (see ``RecoveryPolicy``)."""
        self._require()
        try:
            state = self._read()
        except LinkLost as exc:
            self._recover(exc)
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
            try:
                self._send(safe)
            except LinkLost as exc:
                self._recover(exc)  # re-seeds the step bound from the measured pose
                safe = self.spec.clamp(positions, self._last_sent)
                self._send(safe)
        except Exception:
            self._resync_needed = True
            raise
        self._last_sent = safe
        return safe.copy()

    def _recover(self, exc: LinkLost) -> None:
        """Reconnect after ``exc``, at most ``recovery.attempts`` times; then read the
        positions back, re-seed the step bound from them and, if torque was on, re-enable it
        holding the measured pose. Raises ``SafetyStop`` (torque off where still possible)
        when the link does not come back, the backend cannot reconnect, or a signal asked
        to stop meanwhile."""
        t0 = time.monotonic()
        self.counters.links_lost += 1
        torque_was_on = self._torque
        goal_before = self._last_sent
        where = type(self).__name__
        last: Exception = exc
        tried = 0
        try:
            if not self.can_reconnect:
                raise self._give_up(
                    f"{where}: link lost ({exc}); this arm cannot reconnect by itself"
                )
            log.warning(
                "%s: link lost (%s); reconnecting (%d attempts)", where, exc, self.recovery.attempts
            )
            for delay in self.recovery.delays():
                if self._interrupted.is_set():
                    break
                time.sleep(delay)
                tried += 1
                self.counters.reconnect_attempts += 1
                try:
                    self._reconnect()
                    measured = self._read().positions
                    if not np.all(np.isfinite(measured)):
                        raise BusError(f"positions read back are not finite: {measured}")
                    if self._interrupted.is_set():
                        break
                    self.resync()  # sets the step bound only if the arm could be read
                    if torque_was_on:
                        self.set_torque(True)
                except BusError as again:
                    last = again
                    log.warning("%s: reconnection %d failed: %s", where, tried, again)
                    continue
                ref = measured if goal_before is None else goal_before
                drift = float(np.max(np.abs(measured - ref)))
                self.counters.reconnects += 1
                log.warning(
                    "%s: reconnected after %.2f s (%d attempt(s)); positions read back, at most "
                    "%.3f rad from the last goal; torque %s",
                    where, time.monotonic() - t0, tried, drift,
                    "re-enabled" if torque_was_on else "left off",
                )  # fmt: skip
                return
            if self._interrupted.is_set():
                raise self._give_up(f"{where}: link lost ({exc}); stopped by a signal")
            raise self._give_up(
                f"{where}: link lost ({exc}) and not back after {tried} reconnection(s) over "
                f"{time.monotonic() - t0:.1f} s (last: {last})"
            )
        finally:
            self.counters.recovery_s += time.monotonic() - t0

    def _give_up(self, message: str) -> SafetyStop:
        """Torque off where the servos can still be reached; the ``SafetyStop`` to raise."""
        self.counters.stops_after_link_loss += 1
        self._emergency_torque_off()
        return SafetyStop(
            f"safety stop: {message}; {self._torque_off_words()}; the run can be resumed"
        )

    def _torque_off_words(self) -> str:
        """What a stop after a lost link says of the torque (a backend that knows more, e.g.
        which drives could not confirm, says that)."""
        return (
            "torque off where the servos can be reached (a servo cut off from the host keeps "
            "its last goal)"
        )

    def set_torque(self, enabled: bool) -> None:
        """Enable or disable torque on every joint.

        Enabling first sets the goal to the measured positions (one ``max_step`` towards the
        limits if the arm is outside them), so a limp arm moved by hand does not jump back to
        its last command, nor to a limit.
        """
        self._require()
        if enabled:
            measured = self._read().positions
            here = self.spec.clamp(measured, measured)
            try:
                self._send(here)
            except Exception:
                self._resync_needed = True  # as in ``command``: that goal's fate is unknown
                raise
            self._last_sent = here
        self._set_torque(enabled)
        self._torque = enabled

    def interrupt(self) -> None:
        """Cut torque now, from any thread (the signal watcher of
        ``robot.signals.torque_off_on_signals``), and keep it off: a link recovery in progress
        gives up instead of turning it back on, until ``clear_interrupt`` or the next
        ``connect``. Never raises (a failed torque-off is logged)."""
        self.interrupted_at = time.monotonic()
        self._interrupted.set()
        self._emergency_torque_off()

    def clear_interrupt(self) -> None:
        """Let recoveries turn torque back on again (a new run on a connected arm)."""
        self._interrupted.clear()

    def _emergency_torque_off(self) -> None:
        try:
            self._set_torque(False)
        except Exception as exc:
            log.error("emergency torque off failed: %s", exc)
        self._torque = False

    def emergency_payload(self) -> EmergencyPayload | None:
        """The shared bytes that cut this arm's torque when written to its port by another
        process (``robot.torque_guardian``), kept current by the backend; None (the default)
        where the bus is not a serial port that can be opened by path."""
        return None

    def _torque_off_sent(self) -> None:
        """Backends call this as soon as a torque-off command has left the host (before any
        confirmation): stamps ``torque_off_sent_at``."""
        self.torque_off_sent_at = time.monotonic()

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

    def _reconnect(self) -> None:
        """Close what is left of the link and open it again (only called when
        ``can_reconnect``); raises a ``BusError`` when the link is not back. Sets
        ``self._torque`` from what the servos report, as ``_connect`` does."""
        try:
            self._disconnect()
        except Exception as exc:  # the link is gone already: closing may fail
            log.debug("closing the lost link: %s", exc)
        self._connect()
