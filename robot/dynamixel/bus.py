"""A Dynamixel Protocol 2.0 bus over a serial port (pyserial), with bounded retries and typed
errors.

- Each call sends one instruction packet and waits for the status packets it implies, with a
  timeout computed from the baud rate, the bytes on the wire, the servos' return delay and the
  adapter's latency.
- A call that gets no status (``NoStatusError``) or a corrupt one (``CorruptPacketError``) is
  retried at most ``retries`` times; a sync read retries only the servos that did not answer.
  ``counters`` keeps totals (retries, timeouts, CRC errors, servo errors, alerts).
- A servo that reports an error raises ``ServoError`` (not retried: it will say the same
  again). A status with the alert bit set raises ``HardwareAlertError`` after reading and
  decoding the servo's Hardware Error Status.
- A port that fails mid-call (unplugged adapter, closed pty) raises ``PortLostError``, a
  ``robot.errors.LinkLost``: ``robot.Arm`` then reopens it by name (bounded attempts).
- The port is opened by path (``/dev/ttyUSB0``, a pty) or by pyserial URL (``loop://``). Port
  missing, busy or refusing the baud rate gives a one-line ``BusError``.

Half-duplex adapters echo every byte sent; the decoder returns that echo as an instruction
packet and the bus ignores it.
"""

from __future__ import annotations

import contextlib
import logging
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, fields
from typing import Any, Protocol

from robot.bus_guard import BusGuard
from robot.dynamixel import protocol as proto
from robot.dynamixel.control_table import XL320, Model
from robot.errors import BusError, LinkLost

try:  # pyserial's flush and buffer resets call termios, whose errors are not OSErrors
    from termios import error as _TermiosError
except ImportError:  # pragma: no cover - not a POSIX system
    _TermiosError = OSError  # type: ignore[misc,assignment]

log = logging.getLogger(__name__)

# The Ergo Jr's XL-320 run at 1 Mbps (ROBOTIS e-manual, Poppy Ergo Jr configuration).
DEFAULT_BAUD = 1_000_000
# Serial frame: 1 start + 8 data + 1 stop bits, no parity (e-manual, "Communication": 8N1).
BITS_PER_BYTE = 10
# Factory return delay time: 250 x 2 us = 500 us (e-manual, "Return Delay Time"); the arm sets
# it to 0 when it can, and tells the bus.
DEFAULT_RETURN_DELAY_S = 500e-6
# Slack added to every timeout for the USB-serial adapter and the OS: an FTDI adapter's
# latency timer is 16 ms by default (FTDI AN232B-04; docs/facts.md), plus 4 ms of scheduling slack
# (guess). Tune it down (e.g. 3 ms) with a latency timer of 1 ms.
DEFAULT_LATENCY_S = 0.020
# Retries per call after the first attempt. Guess: two lost packets in a row are rare on a
# healthy bus, three mean something is wrong.
DEFAULT_RETRIES = 2
# How long one serial read may block while waiting (pyserial timeout), s. Small, so the
# deadline is kept to about this precision; not a protocol figure.
POLL_S = 0.001
# Bytes of a status packet besides its parameters: header 4, id 1, length 2, instruction 1,
# error 1, CRC 2 (e-manual, "Status Packet").
STATUS_OVERHEAD = 11


class DynamixelError(BusError):
    """Base of the Dynamixel bus errors."""


class PortLostError(DynamixelError, LinkLost):
    """The serial port failed under the bus (adapter unplugged, pty closed): a ``LinkLost``,
    which the arm answers by reopening the port by name."""


class CallPreemptedError(DynamixelError):
    """A call gave up because another thread took the bus for an emergency torque off."""


class NoStatusError(DynamixelError):
    """No status packet arrived in time (servo absent, unpowered, wrong id or baud rate).

    Attributes:
        ids: the servos that did not answer.
    """

    def __init__(self, message: str, ids: Sequence[int] = ()) -> None:
        super().__init__(message)
        self.ids = list(ids)


class CorruptPacketError(DynamixelError):
    """Status packets arrived but failed their CRC (noise, wrong baud rate, collision)."""

    def __init__(self, message: str, ids: Sequence[int] = ()) -> None:
        super().__init__(message)
        self.ids = list(ids)


class ServoError(DynamixelError):
    """A servo answered with an error in its status packet.

    Attributes:
        servo_id: who answered.
        error: the decoded error byte.
    """

    def __init__(self, message: str, servo_id: int, error: proto.StatusError) -> None:
        super().__init__(message)
        self.servo_id = servo_id
        self.error = error


class HardwareAlertError(ServoError):
    """A servo raised its alert bit; its Hardware Error Status was read and decoded.

    Attributes:
        hardware_status: the raw Hardware Error Status byte (-1 if it could not be read).
        bits: names of the bits set (e.g. ["overload"]).
        data: what the call had read before the alert (id -> bytes), for callers that want it.
    """

    def __init__(
        self,
        message: str,
        servo_id: int,
        error: proto.StatusError,
        hardware_status: int,
        bits: list[str],
        data: Mapping[int, bytes] | None = None,
    ) -> None:
        super().__init__(message, servo_id, error)
        self.hardware_status = hardware_status
        self.bits = bits
        self.data = dict(data or {})


@dataclass
class BusCounters:
    """Totals since the bus was created (or ``reset``)."""

    calls: int = 0
    retries: int = 0  # extra attempts made after a timeout or a corrupt reply
    timeouts: int = 0  # attempts that ended with missing replies and nothing corrupt
    crc_errors: int = 0  # corrupt frames received, and CRC errors reported by servos
    servo_errors: int = 0  # status packets with an error number (ServoError raised)
    alerts: int = 0  # status packets with the alert bit (HardwareAlertError raised)
    # total duration of the calls that needed a retry, s: an upper bound of what the faults
    # cost (the first attempt's wait for the timeout, then the retries)
    retried_call_s: float = 0.0

    def reset(self) -> None:
        for f in fields(self):
            setattr(self, f.name, 0)

    def as_dict(self) -> dict[str, float]:
        return {f.name: getattr(self, f.name) for f in fields(self)}


@dataclass(frozen=True)
class PingReply:
    """A servo's answer to PING."""

    id: int
    model_number: int
    firmware: int


class SerialLike(Protocol):
    """What the bus needs of a pyserial ``Serial`` (an in-process fake may stand in)."""

    @property
    def in_waiting(self) -> int: ...

    def read(self, size: int = 1) -> bytes: ...

    def write(self, data: bytes) -> int | None: ...

    def flush(self) -> None: ...

    def reset_input_buffer(self) -> None: ...

    def close(self) -> None: ...


def open_serial(port: str, baud: int) -> Any:
    """Open ``port`` (a path or a pyserial URL such as ``loop://``) at ``baud`` with a short
    read timeout; one-line ``BusError`` when that fails."""
    import serial  # pyserial; imported here so that the codec works without it

    try:
        if "://" in port:
            return serial.serial_for_url(port, baudrate=baud, timeout=POLL_S)
        return serial.Serial(port, baudrate=baud, timeout=POLL_S, exclusive=True)
    except ValueError as exc:
        raise BusError(f"cannot open Dynamixel bus {port} at {baud} baud: {exc}") from exc
    except serial.SerialException as exc:
        raise BusError(_explain_open_error(port, baud, exc)) from exc


def _explain_open_error(port: str, baud: int, exc: Exception) -> str:
    text = str(exc)
    errno = getattr(exc, "errno", None)
    if errno == 2 or "No such file" in text:
        why = "no such port (unplugged? check `ls /dev/ttyUSB* /dev/ttyACM*`)"
    elif errno == 13 or "Permission denied" in text:
        why = "permission denied (add your user to the dialout group)"
    elif errno in (11, 16) or "lock" in text or "busy" in text.lower():
        why = "port busy (another program has it open)"
    elif "baud" in text.lower():
        why = f"the port refuses {baud} baud"
    else:
        why = text.splitlines()[0] if text else type(exc).__name__
    return f"cannot open Dynamixel bus {port}: {why}"


class DynamixelBus:
    """Protocol 2.0 transactions over one serial port.

    Args:
        port: serial device path or pyserial URL.
        baud: baud rate, bit/s (the Ergo Jr's XL-320s run at 1 Mbps).
        retries: extra attempts per call after a timeout or a corrupt packet.
        latency_s: slack added to every timeout, s (adapter latency + OS).
        return_delay_s: the servos' return delay time, s (``2 us x`` the register value).
        models: servo id -> Model, for the Hardware Error Status address (XL-320 if absent).
        connection: an already open serial-like object (tests, emulators); ``port`` is then
            only a name for messages.
    """

    def __init__(
        self,
        port: str,
        baud: int = DEFAULT_BAUD,
        *,
        retries: int = DEFAULT_RETRIES,
        latency_s: float = DEFAULT_LATENCY_S,
        return_delay_s: float = DEFAULT_RETURN_DELAY_S,
        models: Mapping[int, Model] | None = None,
        connection: SerialLike | None = None,
    ) -> None:
        if baud <= 0:
            raise BusError(f"baud rate must be positive, got {baud}")
        if retries < 0:
            raise BusError(f"retries must be >= 0, got {retries}")
        if not latency_s >= 0:
            raise BusError(f"latency_s must be >= 0 s, got {latency_s}")
        self.port = port
        self.baud = baud
        self.retries = retries
        self.latency_s = latency_s
        self.return_delay_s = return_delay_s
        self.models: dict[int, Model] = dict(models or {})
        self.status_return_level = 2  # 2: every instruction gets a status (e-manual default)
        self.counters = BusCounters()
        self.last_call_retries = 0
        self._serial: SerialLike | None = connection
        self._decoder = proto.Decoder()
        # one call at a time; a torque-off from another thread preempts it (robot/bus_guard.py)
        self.guard = BusGuard(
            lambda: CallPreemptedError(
                f"call on {self.port} given up: another thread is cutting torque"
            )
        )
        self._last_bad = 0

    # ---- lifecycle ---------------------------------------------------------------------------
    @property
    def is_open(self) -> bool:
        return self._serial is not None

    def open(self) -> None:
        if self._serial is None:
            self._serial = open_serial(self.port, self.baud)

    def close(self) -> None:
        """Close the port; never raises (a port that vanished may fail to close)."""
        if self._serial is not None:
            try:
                self._serial.close()
            except (OSError, _TermiosError) as exc:
                log.debug("closing %s: %s", self.port, exc)
            finally:
                self._serial = None

    def __enter__(self) -> DynamixelBus:
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def model_of(self, servo_id: int) -> Model:
        return self.models.get(servo_id, XL320)

    # ---- timing ------------------------------------------------------------------------------
    def wire_time(self, n_bytes: int) -> float:
        """Seconds to move ``n_bytes`` at the baud rate (10 bits a byte)."""
        return n_bytes * BITS_PER_BYTE / self.baud

    def timeout_for(self, request_bytes: int, reply_params: Sequence[int]) -> float:
        """Time to wait for all status packets after sending ``request_bytes``, s.

        Args:
            request_bytes: length of the instruction packet on the wire.
            reply_params: parameter bytes of each expected status packet, in reply order.
        """
        reply_bytes = sum(STATUS_OVERHEAD + n for n in reply_params)
        return (
            self.wire_time(request_bytes + reply_bytes)
            + len(reply_params) * self.return_delay_s
            + self.latency_s
        )

    # ---- one exchange ------------------------------------------------------------------------
    def _exchange(
        self, packet: proto.InstructionPacket, expect: Mapping[int, int]
    ) -> tuple[dict[int, proto.StatusPacket], int]:
        """Send ``packet`` and collect status packets from the ids in ``expect`` (id -> number
        of parameter bytes). Returns (replies by id, corrupt frames seen)."""
        if self._serial is None:
            raise BusError(f"Dynamixel bus {self.port} is not open")
        ser = self._serial
        wire = packet.encode()
        try:
            ser.reset_input_buffer()  # late replies of an earlier call must not match this one
            self._decoder.reset()
            ser.write(wire)
            ser.flush()
            if not expect:
                return {}, 0
            deadline = time.monotonic() + self.timeout_for(len(wire), list(expect.values()))
            got: dict[int, proto.StatusPacket] = {}
            corrupt = 0
            last_look = False
            while len(got) < len(expect) and not last_look:
                # once past the deadline, one last look at what already arrived: a host that
                # was not scheduled for a while must not time out on a reply sitting in its
                # buffer (the retry would flush it)
                last_look = time.monotonic() >= deadline
                self.guard.check()
                chunk = ser.read(ser.in_waiting) if last_look else ser.read(max(1, ser.in_waiting))
                if not chunk:
                    continue
                for item in self._decoder.feed(chunk):
                    if isinstance(item, proto.CorruptFrame):
                        corrupt += 1
                        self.counters.crc_errors += 1
                    elif isinstance(item, proto.StatusPacket) and item.id in expect:
                        got.setdefault(item.id, item)
                    # instruction packets are our own echo; other statuses are strays
            return got, corrupt
        except (OSError, _TermiosError) as exc:  # serial.SerialException: unplugged mid-run
            detail = " ".join(str(exc).split()) or type(exc).__name__
            raise PortLostError(f"Dynamixel bus {self.port} failed: {detail}") from exc

    def _call(
        self,
        build: Callable[[list[int]], proto.InstructionPacket],
        expect: Mapping[int, int],
        what: str,
        retries: int | None = None,
        check_alert: bool = True,
    ) -> dict[int, bytes]:
        """Run one call with retries.

        Args:
            build: ids still to be answered -> the instruction packet to send.
            expect: id -> parameter bytes of its status (empty: no reply expected).
            what: the call in words, for messages ("READ 37+2 from servo 3").
            retries: override of ``self.retries``.
            check_alert: raise ``HardwareAlertError`` when a status has the alert bit.

        Returns:
            id -> status parameters.
        """
        retries = self.retries if retries is None else retries
        with self.guard.hold():
            self.guard.check()
            self.counters.calls += 1
            self.last_call_retries = 0
            pending = dict(expect)
            data: dict[int, bytes] = {}
            alerts: list[tuple[int, proto.StatusError]] = []
            corrupt = 0
            started = time.monotonic()
            try:
                for attempt in range(retries + 1):
                    if attempt:
                        self.counters.retries += 1
                        self.last_call_retries += 1
                    got, corrupt = self._exchange(build(list(pending)), pending)
                    if not pending:
                        return {}
                    self._take(got, pending, data, alerts, what, check_alert)
                    corrupt += self._last_bad
                    if not pending:
                        break
                    if not corrupt:
                        self.counters.timeouts += 1
            finally:
                if self.last_call_retries:
                    self.counters.retried_call_s += time.monotonic() - started
            if pending:
                ids = ", ".join(str(i) for i in pending)
                tries = retries + 1
                if corrupt:
                    raise CorruptPacketError(
                        f"corrupt status from servo(s) {ids} to {what} on {self.port} after "
                        f"{tries} tries (noise, or the wrong baud rate?)",
                        list(pending),
                    )
                raise NoStatusError(
                    f"no status packet from servo(s) {ids} to {what} on {self.port} at "
                    f"{self.baud} baud after {tries} tries (unpowered, wrong id or baud rate?)",
                    list(pending),
                )
            if alerts:
                self._raise_alert(alerts[0][0], alerts[0][1], what, data)
            return data

    def _take(
        self,
        got: Mapping[int, proto.StatusPacket],
        pending: dict[int, int],
        data: dict[int, bytes],
        alerts: list[tuple[int, proto.StatusError]],
        what: str,
        check_alert: bool,
    ) -> None:
        """Move the good replies of ``got`` from ``pending`` to ``data``; sets ``_last_bad``
        to the replies that must be asked again (CRC error reported, wrong length)."""
        self._last_bad = 0
        for sid, status in got.items():
            err = status.status_error
            if err.code == proto.CRC_ERROR:  # the servo got our packet damaged: retry
                self.counters.crc_errors += 1
                self._last_bad += 1
                continue
            if err.code:
                self.counters.servo_errors += 1
                raise ServoError(f"servo {sid} reported {err} to {what} on {self.port}", sid, err)
            if len(status.params) != pending[sid]:
                self.counters.crc_errors += 1
                self._last_bad += 1
                continue
            if err.alert and check_alert:
                self.counters.alerts += 1
                alerts.append((sid, err))
            data[sid] = status.params
            del pending[sid]

    def preempt(self) -> contextlib.AbstractContextManager[None]:
        """Hold the bus for an emergency (torque off) from any thread: a call in progress in
        another thread gives up at its next poll (within ``POLL_S``, raising
        ``CallPreemptedError``) instead of running its timeouts and retries out, so the
        emergency waits for at most one read of the port. In the thread that already holds
        the bus (a signal handler inside a call), the calls just nest (``BusGuard.preempt``)."""
        return self.guard.preempt()

    def _raise_alert(
        self, servo_id: int, err: proto.StatusError, what: str, data: Mapping[int, bytes]
    ) -> None:
        model = self.model_of(servo_id)
        try:
            status = self.read_register(servo_id, "hardware_error", check_alert=False)
            bits = model.decode_hardware_error(status)
            detail = ", ".join(bits) or "no bit set"
        except DynamixelError as exc:
            status, bits, detail = -1, [], f"its Hardware Error Status is unreadable: {exc}"
        raise HardwareAlertError(
            f"servo {servo_id} raised a hardware alert ({detail}) during {what} on {self.port}",
            servo_id,
            err,
            status,
            bits,
            data,
        )

    def _one(self, servo_id: int, n_params: int, reply: bool = True) -> dict[int, int]:
        if servo_id == proto.BROADCAST_ID or not reply:
            return {}
        return {servo_id: n_params}

    # ---- instructions ------------------------------------------------------------------------
    def ping(self, servo_id: int, retries: int | None = None) -> PingReply:
        """PING one servo: its model number and firmware version."""
        pkt = proto.ping(servo_id)
        data = self._call(lambda _: pkt, {servo_id: 3}, f"PING servo {servo_id}", retries, False)
        model, firmware = proto.parse_ping_reply(data[servo_id])
        return PingReply(servo_id, model, firmware)

    def read(self, servo_id: int, address: int, length: int, *, check_alert: bool = True) -> bytes:
        """READ ``length`` bytes at ``address`` of one servo."""
        pkt = proto.read(servo_id, address, length)
        what = f"READ {address}+{length} from servo {servo_id}"
        return self._call(lambda _: pkt, {servo_id: length}, what, check_alert=check_alert)[
            servo_id
        ]

    def write(self, servo_id: int, address: int, data: bytes) -> None:
        """WRITE ``data`` at ``address`` (no reply for broadcast)."""
        pkt = proto.write(servo_id, address, data)
        expect = self._one(servo_id, 0, self.status_return_level >= 2)
        self._call(lambda _: pkt, expect, f"WRITE {address}+{len(data)} to servo {servo_id}")

    def sync_read(self, address: int, length: int, ids: Sequence[int]) -> dict[int, bytes]:
        """SYNC_READ: id -> ``length`` bytes at ``address``; retries ask only the missing ids."""

        def build(pending: list[int]) -> proto.InstructionPacket:
            return proto.sync_read(address, length, pending)

        what = f"SYNC_READ {address}+{length}"
        return self._call(build, dict.fromkeys(ids, length), what)

    def sync_write(self, address: int, length: int, data: Mapping[int, bytes]) -> None:
        """SYNC_WRITE (no reply): ``data[id]`` at ``address`` of each servo."""
        pkt = proto.sync_write(address, length, data)
        self._call(lambda _: pkt, {}, f"SYNC_WRITE {address}+{length}")

    def bulk_read(self, requests: Sequence[tuple[int, int, int]]) -> dict[int, bytes]:
        """BULK_READ: [(id, address, length)] -> id -> bytes; retries ask only missing ids."""
        by_id = {r[0]: r for r in requests}

        def build(pending: list[int]) -> proto.InstructionPacket:
            return proto.bulk_read([by_id[i] for i in pending])

        return self._call(build, {i: r[2] for i, r in by_id.items()}, "BULK_READ")

    def reboot(self, servo_id: int) -> None:
        """REBOOT one servo (clears a hardware-error shutdown; torque comes back off)."""
        pkt = proto.reboot(servo_id)
        self._call(lambda _: pkt, self._one(servo_id, 0), f"REBOOT servo {servo_id}", None, False)

    # ---- registers by name -------------------------------------------------------------------
    def read_register(self, servo_id: int, name: str, *, check_alert: bool = True) -> int:
        """Read one named register (or role, e.g. "hardware_error") of one servo, raw value."""
        reg = self.model_of(servo_id).reg(name)
        return reg.decode(self.read(servo_id, reg.address, reg.size, check_alert=check_alert))

    def write_register(self, servo_id: int, name: str, value: int) -> None:
        """Write one named register (or role) of one servo, raw value."""
        reg = self.model_of(servo_id).reg(name)
        self.write(servo_id, reg.address, reg.encode(value))

    def hardware_error(self, servo_id: int) -> int:
        """The raw Hardware Error Status of one servo."""
        return self.read_register(servo_id, "hardware_error", check_alert=False)
