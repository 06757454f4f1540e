"""CAN bus configuration by python-can's conventions: ``INTERFACE:CHANNEL`` plus a bitrate.

Examples: ``socketcan:can0`` (Linux SocketCAN; the bitrate is set with ``ip link``, not here),
``slcan:/dev/ttyACM0`` (CANable and other SLCAN USB adapters, or a pty), ``virtual:NAME``
(python-can's in-process bus, for tests).

Every failure to parse or open becomes a ``CanBusError`` with a one-line message.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from plumbing.registry import nearest
from robot.errors import BusError

# Interfaces that take a bitrate argument when the bus is opened (python-can docs, per
# interface). socketcan takes it from the kernel (``ip link set can0 type can bitrate ...``),
# virtual has none.
TAKES_BITRATE = frozenset(
    {
        "slcan",
        "pcan",
        "kvaser",
        "gs_usb",
        "seeedstudio",
        "ixxat",
        "vector",
        "canalystii",
        "cantact",
        "systec",
        "usb2can",
        "neovi",
        "nican",
        "iscan",
        "etas",
        "robotell",
        "serial",
    }
)
# Interfaces that talk over an IP network: refused (this project never uses the network for
# CAN, and never UDP multicast).
NETWORK_INTERFACES = frozenset({"udp_multicast", "socketcand"})
# Bitrates an SLCAN adapter can be set to with the ``Sn`` command (Lawicel protocol;
# python-can ``slcanBus._BITRATES``).
SLCAN_BITRATES = (
    10_000,
    20_000,
    50_000,
    100_000,
    125_000,
    250_000,
    500_000,
    750_000,
    1_000_000,
    83_300,
)
# CANopen's usual bitrate for drives (CiA 301 lists 10 k .. 1 M; servo drives run 1 Mbit/s).
DEFAULT_BITRATE = 1_000_000
# python-can waits 2 s after opening an SLCAN serial port (for boards that reset on open);
# a pty does not reset, so we skip the wait there.
PTY_SLEEP_AFTER_OPEN_S = 0.0
# Answers python-can's slcanBus waits for on opening (C, S<n>, an empty command, O: each
# answered by CR, or BEL when refused; python-can 4.6 ``slcanBus.__init__``/``set_bitrate``).
SLCAN_OPENING_COMMANDS = 4
# How long ``open_bus`` waits for an emulated adapter's answers to them, s: a bound against a
# bridge that never answers, not an expectation (it answers in microseconds when idle; guess).
SLCAN_ANSWER_WAIT_S = 2.0

# Longest SLCAN line an adapter sends, bytes: an extended CAN FD frame (``D``/``B``, 8 id digits,
# a DLC digit, 64 data bytes in hex) and its CR (Lawicel protocol, CANable 2.0 FD extension).
# A longer run of bytes without a CR or BEL is garbage: dropped.
MAX_SLCAN_LINE = 1 + 8 + 1 + 128 + 1

# How long the SLCAN reader waits after an error of the port itself before it reads again, s
# (a bound on the notifier thread's spinning on a dead port; the arm notices the loss on its
# next send, within a control period).
PORT_ERROR_PAUSE_S = 0.1

# What to try when an interface fails to open (python-can and Linux SocketCAN docs); socketcan's
# names the interfaces that exist (``socketcan_hint``).
HINTS = {
    "slcan": " (is the adapter plugged in? is another program using the port?)",
}
# Where Linux lists the network interfaces, SocketCAN's channels among them, and the type a CAN
# interface has there (``ARPHRD_CAN``, linux/if_arp.h).
SYS_CLASS_NET = Path("/sys/class/net")
ARPHRD_CAN = 280

EXAMPLES = "e.g. socketcan:can0, slcan:/dev/ttyACM0, virtual:test"


class CanBusError(BusError):
    """The CAN bus spec is malformed or the adapter could not be opened."""


@dataclass(frozen=True)
class CanBusSpec:
    """Where the CAN bus is.

    Attributes:
        interface: python-can interface name (``socketcan``, ``slcan``, ``virtual``, ...).
        channel: interface-specific channel (``can0``, ``/dev/ttyACM0``, a virtual name).
        bitrate: bit/s, or None where the interface does not take one.
    """

    interface: str
    channel: str
    bitrate: int | None = None

    def __str__(self) -> str:
        return f"{self.interface}:{self.channel}"

    def bus_kwargs(self) -> dict[str, Any]:
        """Keyword arguments for ``can.Bus``."""
        kw: dict[str, Any] = {"interface": self.interface, "channel": self.channel}
        if self.bitrate is not None:
            kw["bitrate"] = self.bitrate
        if self.interface == "slcan" and is_pty(self.channel):
            kw["sleep_after_open"] = PTY_SLEEP_AFTER_OPEN_S
        return kw


def is_pty(channel: str) -> bool:
    """A pseudo-terminal, named directly or through a symbolic link (``/dev/pts/N``)."""
    path = channel.split("@", 1)[0]
    return path.startswith("/dev/pts/") or os.path.realpath(path).startswith("/dev/pts/")


def parse_can_spec(spec: str, bitrate: int | None = DEFAULT_BITRATE) -> CanBusSpec:
    """Parse ``INTERFACE:CHANNEL``; the bitrate is kept only for interfaces that take one.

    Raises:
        CanBusError: empty parts, unknown interface, network interface, bad bitrate.
    """
    from can.interfaces import VALID_INTERFACES

    if not isinstance(spec, str) or ":" not in spec:
        raise CanBusError(f"bad CAN bus {spec!r}: expected INTERFACE:CHANNEL, {EXAMPLES}")
    interface, channel = (part.strip() for part in spec.split(":", 1))
    if not interface or not channel:
        raise CanBusError(f"bad CAN bus {spec!r}: expected INTERFACE:CHANNEL, {EXAMPLES}")
    if interface in NETWORK_INTERFACES:
        raise CanBusError(f"CAN interface {interface!r} runs over the network: not allowed here")
    if interface not in VALID_INTERFACES:
        known = ", ".join(sorted(VALID_INTERFACES - NETWORK_INTERFACES))
        raise CanBusError(f"unknown CAN interface {interface!r} in {spec!r}; known: {known}")
    if interface not in TAKES_BITRATE:
        return CanBusSpec(interface, channel, None)
    if bitrate is None:
        bitrate = DEFAULT_BITRATE
    if not isinstance(bitrate, int) or isinstance(bitrate, bool) or bitrate <= 0:
        raise CanBusError(f"bad CAN bitrate {bitrate!r}: expected a positive integer in bit/s")
    if interface == "slcan" and bitrate not in SLCAN_BITRATES:
        allowed = ", ".join(str(b) for b in sorted(SLCAN_BITRATES))
        raise CanBusError(f"SLCAN cannot run at {bitrate} bit/s; choose one of {allowed}")
    return CanBusSpec(interface, channel, bitrate)


def open_bus(spec: CanBusSpec | str, bitrate: int | None = DEFAULT_BITRATE) -> Any:
    """Open a python-can bus (``can.BusABC``); a missing adapter is a one-line ``CanBusError``.

    Args:
        spec: a ``CanBusSpec`` or an ``INTERFACE:CHANNEL`` string.
        bitrate: used when ``spec`` is a string, bit/s.
    """
    if isinstance(spec, str):
        spec = parse_can_spec(spec, bitrate)
    if (
        spec.interface in ("slcan", "serial")
        and spec.channel.startswith("/")
        and not (os.path.exists(spec.channel.split("@", 1)[0]))
    ):
        raise CanBusError(f"cannot open CAN bus {spec}: no such device {spec.channel}")
    import can

    try:
        if spec.interface == "slcan":
            kwargs = spec.bus_kwargs()
            del kwargs["interface"]
            bus = tolerant_slcan_bus()(**kwargs)
        else:
            bus = can.Bus(**spec.bus_kwargs())
    except (can.CanError, OSError, ValueError, ImportError, NotImplementedError) as exc:
        detail = " ".join(str(exc).split()) or type(exc).__name__
        hint = socketcan_hint(spec.channel) if spec.interface == "socketcan" else ""
        hint = hint or HINTS.get(spec.interface, "")
        raise CanBusError(f"cannot open CAN bus {spec}: {detail}{hint}") from exc
    if spec.interface == "slcan" and is_pty(spec.channel):
        _await_opening_answers(bus)
    return bus


def can_interfaces(root: Path | None = None) -> list[str]:
    """The CAN network interfaces of this machine (SocketCAN's channels: ``can0``, ``vcan0``),
    sorted: those of ``root`` (default ``SYS_CLASS_NET``) whose ``type`` is ``ARPHRD_CAN``."""
    root = SYS_CLASS_NET if root is None else root
    found = []
    try:
        entries = list(root.iterdir())
    except OSError:
        return []
    for entry in entries:
        try:
            if int((entry / "type").read_text().strip()) == ARPHRD_CAN:
                found.append(entry.name)
        except (OSError, ValueError):
            continue
    return sorted(found)


def socketcan_hint(channel: str) -> str:
    """What to try when ``socketcan:CHANNEL`` fails to open, in parentheses: bring it up when
    it exists; else the CAN interfaces that do (the nearest first), or that there is none."""
    found = can_interfaces()
    up = "sudo ip link set {} up type can bitrate " + str(DEFAULT_BITRATE)
    if channel in found:
        return f" (is {channel} up? {up.format(channel)})"
    if not found:
        return (
            f" (no CAN interface {channel!r}: this machine has none; is the adapter plugged in "
            "and its driver loaded? `ip link` lists them; a USB adapter that speaks SLCAN is "
            "slcan:/dev/ttyACM0)"
        )
    near = nearest(channel, found)
    hint = "" if near is None else f" (did you mean socketcan:{near}?)"
    return (
        f" (no CAN interface {channel!r}: this machine has {', '.join(found)}{hint}; bring "
        f"one up with: {up.format(near or found[0])})"
    )


def _await_opening_answers(bus: Any) -> None:
    """Read an emulated SLCAN adapter's answers to the opening commands before anything else
    reads the port. The emulator (``sim.canopen.server``) flushes what a dead client left
    queued when it handles C; a reader already running then (the CANopen network's notifier
    thread) can find the data it was told of gone, which pyserial reports as "device reports
    readiness to read but returned no data". Once C, S, the empty command and O are answered,
    the flush is over. Frames read meanwhile are a dead client's: dropped, as the flush does.
    Gives up quietly after ``SLCAN_ANSWER_WAIT_S`` (the first read then tells what is wrong)."""
    import serial

    port = bus.serialPortOrig  # python-can's pyserial port (slcanBus attribute)
    answers, line = 0, b""
    deadline = time.monotonic() + SLCAN_ANSWER_WAIT_S
    while answers < SLCAN_OPENING_COMMANDS and time.monotonic() < deadline:
        try:
            chunk = port.read(max(1, port.in_waiting))
        except serial.SerialException:
            continue  # the flush emptied what select() had seen: read again
        for byte in chunk:
            if byte == 0x07:  # BEL: a command refused (answered all the same)
                answers += 1
            elif byte == 0x0D:
                answers += line == b""  # a bare CR answers a command; "t...CR" is a frame
                line = b""
            else:
                line += bytes([byte])


_TOLERANT_SLCAN: Any = None


def garbled_words(lines: int) -> str:
    """``"; N garbled line(s) from the adapter dropped: ..."`` for ``lines`` > 0, else ``""``:
    what a message about silent nodes adds when the serial line itself is the likely cause."""
    if lines <= 0:
        return ""
    return (
        f"; {lines} garbled line(s) from the adapter dropped: noise on the serial line, a wrong "
        f"baud rate, or not an SLCAN adapter?"
    )


def tolerant_slcan_bus() -> Any:
    """python-can's SLCAN bus class, made to drop a garbled line instead of dying.

    python-can (4.6) decodes each line the adapter sends as it comes: a byte that is not ASCII
    raises ``UnicodeDecodeError`` (wrapped in ``CanOperationError``, the garbled bytes left in
    its buffer, so every later line fails too), a bad hex digit or a short line a
    ``ValueError``/``IndexError``. In the CANopen network's notifier thread any of them ends
    the thread (a traceback on stderr) and every later send re-raises it: noise on the serial
    line for a few milliseconds cut the host off from its drives for good. This class drops
    such a line, as a CAN controller drops a frame that fails its CRC, and counts it
    (``garbled_lines``; ``garbled_at``: when the last one came, ``time.monotonic`` s): the
    frames lost with it are late or missing TPDOs, heartbeats and SDO answers, which the
    arm's usual bounds deal with. An error of the port itself (EIO: unplugged) is kept in
    ``port_error`` and the reader waits ``PORT_ERROR_PAUSE_S`` before reading again, instead
    of ending the notifier thread with a traceback: the next send on the dead port fails and
    the arm takes that for a lost link (and reconnects).

    SLCAN has no checksum: garbage that happens to spell a valid line (``t``, three hex
    digits, a DLC digit, that many hex bytes, CR) is taken for a frame. Random bytes rarely do
    (``t`` then 4+ constrained ASCII characters: below 1e-8 a byte).
    """
    global _TOLERANT_SLCAN
    if _TOLERANT_SLCAN is not None:
        return _TOLERANT_SLCAN
    import can
    from can.interfaces.slcan import slcanBus

    class TolerantSlcanBus(slcanBus):
        garbled_lines = 0
        garbled_at = 0.0
        port_error: BaseException | None = None

        def _garbled(self) -> tuple[None, bool]:
            self._buffer.clear()
            self.garbled_lines += 1
            self.garbled_at = time.monotonic()
            return None, False

        def unread_bytes(self) -> int:
            """Bytes the adapter sent that this host has not decoded yet: waiting in the
            port, or read into the line buffer (0 when the port cannot say)."""
            try:
                return int(self.serialPortOrig.in_waiting) + len(self._buffer)
            except Exception:  # a closed or failed port: nothing known to be waiting
                return 0

        def _recv_internal(self, timeout: float | None) -> tuple[Any, bool]:
            if len(self._buffer) > MAX_SLCAN_LINE:
                return self._garbled()
            try:
                msg, filtered = super()._recv_internal(timeout)
            except can.CanOperationError as exc:
                if isinstance(exc.__cause__, UnicodeDecodeError):
                    return self._garbled()
                # the port itself failed (unplugged: EIO): say so to whoever looks, and let the
                # reader thread wait rather than die with a traceback; the next send fails on
                # the same port and the arm takes it for a lost link
                self.port_error = exc.__cause__ or exc
                time.sleep(min(timeout if timeout is not None else PORT_ERROR_PAUSE_S,
                               PORT_ERROR_PAUSE_S))  # fmt: skip
                return None, False
            except (ValueError, IndexError, KeyError):
                return self._garbled()
            if msg is not None and not msg.is_remote_frame and len(msg.data) != msg.dlc:
                return self._garbled()  # fewer hex bytes than its DLC says
            return msg, filtered

    _TOLERANT_SLCAN = TolerantSlcanBus
    return TolerantSlcanBus
