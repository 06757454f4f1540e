"""SLCAN (Lawicel ASCII) codec, adapter side: what a CANable-like USB adapter does with the
lines a host writes to its serial port, and how it reports received CAN frames.

Pure: no I/O, no python-can, so it can be fuzzed. Protocol facts (Lawicel CAN232/CANUSB manual;
python-can ``interfaces/slcan.py`` is the host side we must interoperate with):

- every command and reply ends with ``\\r``; an error reply is BEL ``\\a``;
- ``tIIILDD..`` standard data frame (3 hex id, 1 dlc digit, 2 hex per byte),
  ``TIIIIIIIILDD..`` extended, ``rIIIL`` / ``RIIIIIIIIL`` remote frames;
  a transmitted frame is acknowledged with ``z\\r`` (standard) or ``Z\\r`` (extended);
- ``O`` open, ``L`` open listen-only, ``C`` close, ``Sn`` bitrate code (0..8, python-can
  adds 9 = 83.3 kbit/s), ``sxxyy`` BTR registers, ``V`` version, ``N`` serial number,
  ``F`` status flags. Frames can be sent only while open, bitrates set only while closed.
"""

from __future__ import annotations

from dataclasses import dataclass, field

OK = b"\r"
ERROR = b"\a"
# Bitrate codes of the ``S`` command, bit/s (Lawicel manual; 9 is python-can's extension).
BITRATES = {
    0: 10_000,
    1: 20_000,
    2: 50_000,
    3: 100_000,
    4: 125_000,
    5: 250_000,
    6: 500_000,
    7: 750_000,
    8: 1_000_000,
    9: 83_300,
}
MAX_STD_ID = 0x7FF
MAX_EXT_ID = 0x1FFFFFFF
# Version and serial number this adapter reports (made up for the emulator).
VERSION_REPLY = b"V1013\r"
SERIAL_REPLY = b"NERGO\r"
# A line longer than the longest valid command (``T`` + 8 + 1 + 16 = 26 chars) is garbage.
MAX_LINE = 64


class SlcanError(ValueError):
    """A line is not valid SLCAN."""


@dataclass(frozen=True)
class CanFrame:
    """A classic CAN frame.

    Attributes:
        can_id: 11-bit (standard) or 29-bit (extended) identifier.
        data: 0..8 bytes (empty for remote frames).
        extended: 29-bit identifier.
        remote: remote transmission request (no data, ``dlc`` bytes requested).
        dlc: data length code for remote frames (== len(data) otherwise).
    """

    can_id: int
    data: bytes = b""
    extended: bool = False
    remote: bool = False
    dlc: int = field(default=-1)

    def __post_init__(self) -> None:
        limit = MAX_EXT_ID if self.extended else MAX_STD_ID
        if not 0 <= self.can_id <= limit:
            raise SlcanError(f"CAN id 0x{self.can_id:X} out of range 0..0x{limit:X}")
        if len(self.data) > 8:
            raise SlcanError(f"CAN frame with {len(self.data)} data bytes (at most 8)")
        if self.remote and self.data:
            raise SlcanError("a remote frame carries no data")
        dlc = len(self.data) if self.dlc < 0 else self.dlc
        if not 0 <= dlc <= 8 or (not self.remote and dlc != len(self.data)):
            raise SlcanError(f"bad DLC {self.dlc} for {len(self.data)} data bytes")
        object.__setattr__(self, "dlc", dlc)
        object.__setattr__(self, "data", bytes(self.data))


def encode_frame(frame: CanFrame) -> bytes:
    """The line an adapter sends to the host for a received frame, ``\\r`` included."""
    if frame.remote:
        head = f"R{frame.can_id:08X}" if frame.extended else f"r{frame.can_id:03X}"
        return f"{head}{frame.dlc}\r".encode()
    head = f"T{frame.can_id:08X}" if frame.extended else f"t{frame.can_id:03X}"
    return f"{head}{frame.dlc}{frame.data.hex().upper()}\r".encode()


def _hex(text: str, what: str) -> int:
    if not text or any(c not in "0123456789abcdefABCDEF" for c in text):
        raise SlcanError(f"bad hex {what} {text!r}")
    return int(text, 16)


def decode_frame(line: bytes | str) -> CanFrame:
    """Parse one ``t``/``T``/``r``/``R`` line (with or without the trailing ``\\r``).

    Raises:
        SlcanError: not a well-formed frame line.
    """
    if isinstance(line, bytes):
        try:
            line = line.decode("ascii")
        except UnicodeDecodeError as exc:
            raise SlcanError(f"non-ASCII SLCAN line {line[:MAX_LINE]!r}") from exc
    line = line.rstrip("\r")
    if not line or line[0] not in "tTrR":
        raise SlcanError(f"not an SLCAN frame line: {line[:MAX_LINE]!r}")
    extended = line[0] in "TR"
    remote = line[0] in "rR"
    id_len = 8 if extended else 3
    if len(line) < 1 + id_len + 1:
        raise SlcanError(f"SLCAN frame line too short: {line!r}")
    can_id = _hex(line[1 : 1 + id_len], "id")
    dlc_char = line[1 + id_len]
    if dlc_char not in "012345678":
        raise SlcanError(f"bad DLC {dlc_char!r} in {line[:MAX_LINE]!r}")
    dlc = int(dlc_char)
    payload = line[2 + id_len :]
    if remote:
        if payload:
            raise SlcanError(f"remote frame with data: {line[:MAX_LINE]!r}")
        return CanFrame(can_id, b"", extended, True, dlc)
    if len(payload) != 2 * dlc:
        raise SlcanError(f"{len(payload)} hex digits for DLC {dlc} in {line[:MAX_LINE]!r}")
    data = bytes(_hex(payload[i : i + 2], "byte") for i in range(0, len(payload), 2))
    return CanFrame(can_id, data, extended, False, dlc)


class LineSplitter:
    """Cuts a byte stream into ``\\r``-terminated lines. ``\\n`` is ignored (terminals send
    ``\\r\\n``); an over-long line is dropped whole (returned as ``None``) so garbage cannot
    grow the buffer."""

    def __init__(self) -> None:
        self._buf = bytearray()
        self._overflow = False

    def feed(self, chunk: bytes) -> list[bytes | None]:
        """Lines completed by ``chunk`` (without ``\\r``); ``None`` for a dropped long line."""
        out: list[bytes | None] = []
        for byte in chunk:
            if byte == 0x0D:
                out.append(None if self._overflow else bytes(self._buf))
                self._buf.clear()
                self._overflow = False
            elif byte == 0x0A:
                continue
            elif len(self._buf) >= MAX_LINE:
                self._overflow = True
            else:
                self._buf.append(byte)
        return out


@dataclass
class SlcanAdapter:
    """The command state of an SLCAN adapter.

    ``handle(line)`` returns the reply bytes to write back to the host and, for a frame the
    host asked to transmit, the frame to put on the CAN bus.

    Attributes:
        is_open: the CAN channel is open (``O``/``L``), frames flow.
        listen_only: opened with ``L`` (frames received, none transmitted).
        bitrate: bit/s set by ``S`` (None: never set, adapter default).
    """

    is_open: bool = False
    listen_only: bool = False
    bitrate: int | None = None

    def handle(self, line: bytes | None) -> tuple[bytes, CanFrame | None]:
        """Process one line (without ``\\r``); ``None`` (a dropped line) is an error."""
        if line is None:
            return ERROR, None
        if not line:
            return OK, None  # empty command: python-can sends one after ``S``
        cmd = chr(line[0])
        if cmd in "tTrR":
            if not self.is_open or self.listen_only:
                return ERROR, None
            try:
                frame = decode_frame(line)
            except SlcanError:
                return ERROR, None
            return (b"Z\r" if frame.extended else b"z\r"), frame
        if cmd == "O" and len(line) == 1:
            self.is_open, self.listen_only = True, False
            return OK, None
        if cmd == "L" and len(line) == 1:
            self.is_open, self.listen_only = True, True
            return OK, None
        if cmd == "C" and len(line) == 1:
            self.is_open = self.listen_only = False
            return OK, None
        if cmd == "S" and len(line) == 2 and not self.is_open:
            code = line[1] - 0x30
            if code in BITRATES:
                self.bitrate = BITRATES[code]
                return OK, None
            return ERROR, None
        if cmd == "s" and len(line) == 5 and not self.is_open:
            try:
                _hex(line[1:].decode("ascii"), "BTR")
            except (SlcanError, UnicodeDecodeError):
                return ERROR, None
            return OK, None
        if cmd == "V" and len(line) == 1:
            return VERSION_REPLY, None
        if cmd == "N" and len(line) == 1:
            return SERIAL_REPLY, None
        if cmd == "F" and len(line) == 1:
            return b"F00\r", None
        return ERROR, None
