"""A Dynamixel Protocol 2.0 bus over a serial port (pyserial), with bounded retries and typed
errors.

- Each call sends one instruction packet and waits for the status packets it implies, with a
  timeout computed from the baud rate, the bytes on the wire, the servos' return delay and a
  slack for the adapter's and the host's latency: at least ``latency_s``, raised to the
  latency the bus measures (``LatencyEstimate``, as TCP's retransmission timer), at most
  ``MAX_LATENCY_S``; each retry waits twice as long.
- Replies are matched to requests per servo, oldest first (a servo answers in order) and by
  size: a status packet that comes after its call gave up is recognised and set aside
  (``counters.late_replies``), never taken for a later call's answer (the input used to be
  flushed before each call: a reply later than that was read as the next call's, a wrong
  value, or of another size, counted as a CRC error with no fault injected).
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

Beside it: the errors (``bus_errors``), the port (``serial_port``), the matching of replies to
requests and the latency estimate (``replies``).
"""

from __future__ import annotations

import contextlib
import logging
import math
import time
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

from robot.bus_guard import BusGuard
from robot.dynamixel import protocol as proto
from robot.dynamixel.bus_errors import (
    CallPreemptedError,
    CorruptPacketError,
    DynamixelError,
    HardwareAlertError,
    NoStatusError,
    PortLostError,
    ServoError,
)
from robot.dynamixel.control_table import XL320, Model
from robot.dynamixel.replies import (
    MAX_LATENCY_S,
    BusCounters,
    Expected,
    LatencyEstimate,
    Replies,
    question_of,
)
from robot.dynamixel.serial_port import SerialLike, open_serial
from robot.errors import BusError

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
# How long a request's reply is still expected after the call gave up on it, s: a reply later
# than that is taken for one to a later request of the same size. Status packets up to 0.5 s
# late were measured on 2 cores at load 7 (twin serve over a pty, tests/stress/hil_pty.py); a
# reply never expected costs one wait of a later call of the same size (it set the reply
# aside, then takes it), whatever this is. Guess: ten times that.
MATCH_HORIZON_S = 5.0
# Requests remembered per servo while their replies are awaited: a servo that stopped
# answering (unpowered) and comes back costs at most this many waits of later calls before
# its replies line up again. Guess: two calls of three attempts, and some.
MAX_OUTSTANDING = 8
# A surplus request (a retry of a call already answered) is awaited before the next request
# for this many times as long as its attempt waited, then forgotten: a reply later than that
# counts as lost. Guess: twice leaves a host descheduled for as long as the slack itself (at
# load 5-6 on 2 cores, replies 30 ms late were read up to about that late) and costs one such
# wait per lost reply.
SPARE_PATIENCE = 2.0
# Bytes of a status packet besides its parameters: header 4, id 1, length 2, instruction 1,
# error 1, CRC 2 (e-manual, "Status Packet").
STATUS_OVERHEAD = 11


@dataclass(frozen=True)
class PingReply:
    """A servo's answer to PING."""

    id: int
    model_number: int
    firmware: int


class DynamixelBus:
    """Protocol 2.0 transactions over one serial port.

    Args:
        port: serial device path or pyserial URL.
        baud: baud rate, bit/s (the Ergo Jr's XL-320s run at 1 Mbps).
        retries: extra attempts per call after a timeout or a corrupt packet.
        latency_s: the least slack added to every timeout, s (adapter latency + OS); the bus
            raises it to the latency it measures, up to ``max_latency_s``.
        max_latency_s: the most slack the bus adapts to, s (a reply later than that, or than
            ``latency_s`` if larger, counts as lost).
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
        max_latency_s: float = MAX_LATENCY_S,
    ) -> None:
        if baud <= 0:
            raise BusError(f"baud rate must be positive, got {baud}")
        if retries < 0:
            raise BusError(f"retries must be >= 0, got {retries}")
        if not latency_s >= 0:
            raise BusError(f"latency_s must be >= 0 s, got {latency_s}")
        if not max_latency_s >= 0:
            raise BusError(f"max_latency_s must be >= 0 s, got {max_latency_s}")
        self.port = port
        self.baud = baud
        self.retries = retries
        self.latency = LatencyEstimate(latency_s, max_latency_s)
        self.return_delay_s = return_delay_s
        self.models: dict[int, Model] = dict(models or {})
        self.status_return_level = 2  # 2: every instruction gets a status (e-manual default)
        self.counters = BusCounters()
        self.last_call_retries = 0
        #: when the last request left the host (after its write was flushed), ``time.monotonic``
        #: s; NaN before the first: a servo samples what it reports as it reads the request
        self.last_sent_at = math.nan
        self._serial: SerialLike | None = connection
        self._decoder = proto.Decoder()
        # one call at a time; a torque-off from another thread preempts it (robot/bus_guard.py)
        self.guard = BusGuard(
            lambda: CallPreemptedError(
                f"call on {self.port} given up: another thread is cutting torque"
            )
        )
        self._last_bad = 0
        # status packets asked for and not yet received, per servo id, oldest first (a servo
        # answers its requests in order); the call counter tells this call's from older ones
        self._expected: dict[int, deque[Expected]] = {}
        self._call_no = 0

    @property
    def latency_s(self) -> float:
        """The least slack of every timeout, s (``latency.floor``)."""
        return self.latency.floor

    @latency_s.setter
    def latency_s(self, value: float) -> None:
        if not value >= 0:
            raise BusError(f"latency_s must be >= 0 s, got {value}")
        self.latency.floor = value

    # ---- lifecycle ---------------------------------------------------------------------------
    @property
    def is_open(self) -> bool:
        return self._serial is not None

    def open(self) -> None:
        if self._serial is None:
            self._serial = open_serial(self.port, self.baud)
            self._expected.clear()  # a new connection: nothing of the old one will come
            self._decoder.reset()

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

    def timeout_for(
        self, request_bytes: int, reply_params: Sequence[int], attempt: int = 0
    ) -> float:
        """Time to wait for all status packets after sending ``request_bytes``, s: their wire
        time and return delays, plus the slack of that attempt (``latency``).

        Args:
            request_bytes: length of the instruction packet on the wire.
            reply_params: parameter bytes of each expected status packet, in reply order.
            attempt: 0 for a call's first attempt, 1 for its first retry...
        """
        return self._nominal(request_bytes, reply_params) + self.latency.slack_of_attempt(attempt)

    def _nominal(self, request_bytes: int, reply_params: Sequence[int]) -> float:
        """Wire time of the request and the replies, and the replies' return delays, s."""
        reply_bytes = sum(STATUS_OVERHEAD + n for n in reply_params)
        return self.wire_time(request_bytes + reply_bytes) + len(reply_params) * self.return_delay_s

    # ---- one exchange ------------------------------------------------------------------------
    def _exchange(
        self, packet: proto.InstructionPacket, expect: Mapping[int, int], attempt: int = 0
    ) -> tuple[dict[int, proto.StatusPacket], int]:
        """Send ``packet`` and collect status packets from the ids in ``expect`` (id -> number
        of parameter bytes). Returns (replies by id, corrupt frames of this call seen).

        Replies are matched to requests by counting (``Replies``): a servo answers its
        requests in order, so its status packet first answers the oldest request of it not yet
        answered. A late reply to an earlier call is so recognised and set aside
        (``late_replies``) instead of being read as this call's answer, or as garbage; one to an
        earlier attempt of this call answers it (the same question). The count corrects
        itself: a reply nobody seems to wait for, but that this call does, is this call's; and
        when this attempt ends without the reply of a servo, one set aside as late is taken
        (the request it was counted against had lost its reply)."""
        if self._serial is None:
            raise BusError(f"Dynamixel bus {self.port} is not open")
        ser = self._serial
        wire = packet.encode()
        replies = Replies(self, self._call_no, expect)
        try:
            if expect:
                self._settle(ser, expect)
            replies.take(ser.read(ser.in_waiting) if ser.in_waiting else b"")
            ser.write(wire)
            ser.flush()
            sent_at = self.last_sent_at = time.monotonic()
            if not expect:
                return {}, 0
            deadline = sent_at + self.timeout_for(len(wire), list(expect.values()), attempt)
            question = question_of(packet)
            self._register(expect, len(wire), sent_at, deadline, question)
            last_look = False
            while not replies.complete and not last_look:
                # once past the deadline, one last look at what already arrived: a host that
                # was not scheduled for a while must not time out on a reply sitting in its
                # buffer (the retry would ask again)
                last_look = time.monotonic() >= deadline
                self.guard.check()
                chunk = ser.read(ser.in_waiting) if last_look else ser.read(max(1, ser.in_waiting))
                replies.take(chunk)
            if not replies.complete:
                replies.take_set_aside(question)
            if replies.latency is not None:
                self.latency.add(replies.latency)
            return replies.got, replies.corrupt
        except (OSError, _TermiosError) as exc:  # serial.SerialException: unplugged mid-run
            detail = " ".join(str(exc).split()) or type(exc).__name__
            raise PortLostError(f"Dynamixel bus {self.port} failed: {detail}") from exc

    def _settle(self, ser: SerialLike, expect: Mapping[int, int]) -> None:
        """Before a request that expects ``expect`` (id -> parameter bytes): wait for the
        replies still due to surplus requests of the same servos and reply size (the retries
        of a call already answered, or the first attempt of one answered by its retry) up to
        ``SPARE_PATIENCE`` times as long as their attempts waited, take one last look at what
        arrived, then forget those requests. Without it the count drifts: a retry whose first
        attempt's reply had been lost leaves a request nobody will answer, and the next call's
        reply is counted against it; a late first attempt leaves a reply that the next call
        would count against its own request, one call behind for good (and the latency learnt
        would be the calls' spacing, not the replies'). A request of another size waits for
        nothing (a reply is matched by its size: a torque-off WRITE never waits behind a
        READ's retries), nor does one that expects no reply (a broadcast)."""

        def surplus() -> list[Expected]:
            return [
                e
                for sid, n in expect.items()
                for e in self._expected.get(sid, ())
                if e.spare and e.n_params == n
            ]

        pending = Replies(self, -1, {})
        while True:
            now = time.monotonic()
            if not any(e.sent_at + SPARE_PATIENCE * (e.deadline - e.sent_at) > now
                       for e in surplus()):  # fmt: skip
                break
            self.guard.check()
            pending.take(ser.read(max(1, ser.in_waiting)))
        if ser.in_waiting:  # a host late to look must not forget a reply sitting in its buffer
            pending.take(ser.read(ser.in_waiting))
        gone = {id(e) for e in surplus()}
        for sid in expect:
            queue = self._expected.get(sid)
            if queue:
                kept = [e for e in queue if id(e) not in gone]
                queue.clear()
                queue.extend(kept)

    def _register(
        self,
        expect: Mapping[int, int],
        request_bytes: int,
        sent_at: float,
        deadline: float,
        question: bytes,
    ) -> None:
        """Note the status packets a request just sent asks for (in reply order), awaited
        by its attempt until ``deadline`` (monotonic s)."""
        params: list[int] = []
        for sid, n in expect.items():
            params.append(n)
            queue = self._expected.setdefault(sid, deque())
            while queue and queue[0].expires < sent_at:
                queue.popleft()  # older than any reply can be: it was lost
            nominal = self._nominal(request_bytes, params)
            horizon = max(self.latency.longest, MATCH_HORIZON_S)
            expires = sent_at + nominal + horizon
            queue.append(
                Expected(self._call_no, n, sent_at, nominal, expires, False, deadline, question)
            )
            while len(queue) > MAX_OUTSTANDING:
                queue.popleft()  # a servo this far behind is not answering: forget the oldest

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
            self._call_no += 1
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
                    got, corrupt = self._exchange(build(list(pending)), pending, attempt)
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
