"""Dynamixel Protocol 2.0 packets: pure encoding and decoding, no I/O.

Packet layout (ROBOTIS e-manual, "DYNAMIXEL Protocol 2.0"):

    instruction: FF FF FD 00 | ID | LEN_L LEN_H | INST | params ...      | CRC_L CRC_H
    status:      FF FF FD 00 | ID | LEN_L LEN_H | 0x55 | ERR | params ... | CRC_L CRC_H

``LEN`` counts the bytes after itself (instruction, error, params, CRC) *after* byte stuffing;
the CRC covers everything before it, header included, also after stuffing. Multi-byte fields
are little-endian. Byte stuffing: every ``FF FF FD`` from the instruction byte up to the CRC
becomes ``FF FF FD FD``, so that the header ``FF FF FD 00`` never appears inside a packet.

The streaming ``Decoder`` finds packets in a byte stream that may hold garbage, partial packets
and the echo of our own instruction packets (half-duplex adapters echo what they send).
"""

from __future__ import annotations

import struct
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from enum import IntEnum

# Header FF FF FD plus the reserved byte 00 (e-manual, Protocol 2.0 "Header" and "Reserved").
HEADER = b"\xff\xff\xfd\x00"
_STUFF_PATTERN = b"\xff\xff\xfd"
# Broadcast id; ids 0..252 are servo ids, 0xFD and 0xFF are not used (e-manual, Protocol 2.0
# "Packet ID").
BROADCAST_ID = 0xFE
MAX_SERVO_ID = 252
# Header (4) + id (1) + length (2): the fixed prefix before the counted bytes.
PREFIX_SIZE = 7
# Smallest LEN: instruction + CRC (3); status packets have one more byte (the error byte).
MIN_LENGTH = 3
# Longest packet the decoder accepts, counted bytes. The protocol allows 65535 but no packet of
# this project comes near: the XL-320 control table is 53 bytes, a sync read of 253 servos x
# 4 bytes is under 1300. Guess, large enough for any bulk read we issue; a garbage header with a
# larger LEN is dropped at once instead of stalling the stream.
DEFAULT_MAX_LENGTH = 2048
# CRC-16 of Protocol 2.0: polynomial 0x8005, initial value 0, not reflected, no final XOR
# (e-manual, Protocol 2.0 "CRC"; the "CRC-16/BUYPASS" parameters).
CRC_POLY = 0x8005


class Instruction(IntEnum):
    """Instruction codes (e-manual, Protocol 2.0 "Instruction")."""

    PING = 0x01
    READ = 0x02
    WRITE = 0x03
    REG_WRITE = 0x04
    ACTION = 0x05
    FACTORY_RESET = 0x06
    REBOOT = 0x08
    CLEAR = 0x10
    STATUS = 0x55
    SYNC_READ = 0x82
    SYNC_WRITE = 0x83
    FAST_SYNC_READ = 0x8A
    BULK_READ = 0x92
    BULK_WRITE = 0x93


class ProtocolError(ValueError):
    """A packet or its parameters are malformed (one-line message)."""


# ---- CRC ----------------------------------------------------------------------------------
def _make_crc_table() -> tuple[int, ...]:
    table = []
    for i in range(256):
        c = i << 8
        for _ in range(8):
            c = ((c << 1) ^ CRC_POLY) if c & 0x8000 else (c << 1)
        table.append(c & 0xFFFF)
    return tuple(table)


_CRC_TABLE = _make_crc_table()


def crc16(data: bytes | bytearray | memoryview, crc: int = 0) -> int:
    """CRC-16 (poly 0x8005, init ``crc``, not reflected) of ``data``, as an int 0..65535."""
    table = _CRC_TABLE
    for b in bytes(data):
        crc = ((crc << 8) ^ table[((crc >> 8) ^ b) & 0xFF]) & 0xFFFF
    return crc


# ---- byte stuffing ------------------------------------------------------------------------
def stuff(body: bytes) -> bytes:
    """Insert ``FD`` after every ``FF FF FD`` (``body`` = instruction [error] params)."""
    # The pattern cannot overlap itself (it starts with FF, ends with FD), so the non-overlapping
    # left-to-right scan of ``bytes.replace`` finds exactly the occurrences of the input.
    return body.replace(_STUFF_PATTERN, _STUFF_PATTERN + b"\xfd")


def unstuff(body: bytes) -> bytes:
    """Inverse of ``stuff``: ``FF FF FD FD`` -> ``FF FF FD``; ``unstuff(stuff(x)) == x``."""
    return body.replace(_STUFF_PATTERN + b"\xfd", _STUFF_PATTERN)


def _frame(servo_id: int, body: bytes) -> bytes:
    stuffed = stuff(body)
    head = HEADER + bytes([servo_id]) + struct.pack("<H", len(stuffed) + 2) + stuffed
    return head + struct.pack("<H", crc16(head))


def _check_id(servo_id: int, broadcast_ok: bool = True) -> None:
    if not (0 <= servo_id <= MAX_SERVO_ID or (broadcast_ok and servo_id == BROADCAST_ID)):
        raise ProtocolError(f"servo id {servo_id} is not in 0..{MAX_SERVO_ID} (or 254 broadcast)")


# ---- status error byte --------------------------------------------------------------------
# Error byte of a status packet (e-manual, Protocol 2.0 "Status Packet"): bit 7 is the alert
# bit (a hardware error: read Hardware Error Status); the low 7 bits hold an error number.
ALERT_BIT = 0x80
STATUS_ERROR_NAMES: dict[int, str] = {
    1: "result fail",
    2: "instruction error",
    3: "CRC error",
    4: "data range error",
    5: "data length error",
    6: "data limit error",
    7: "access error",
}
RESULT_FAIL, INSTRUCTION_ERROR, CRC_ERROR = 1, 2, 3
DATA_RANGE_ERROR, DATA_LENGTH_ERROR, DATA_LIMIT_ERROR, ACCESS_ERROR = 4, 5, 6, 7


@dataclass(frozen=True)
class StatusError:
    """A decoded status error byte.

    Attributes:
        alert: bit 7, the servo has a hardware error (see its Hardware Error Status).
        code: the low 7 bits, 0 when the instruction succeeded (see ``STATUS_ERROR_NAMES``).
    """

    alert: bool
    code: int

    @classmethod
    def from_byte(cls, byte: int) -> StatusError:
        if not 0 <= byte <= 0xFF:
            raise ProtocolError(f"status error byte {byte} is not in 0..255")
        return cls(alert=bool(byte & ALERT_BIT), code=byte & 0x7F)

    @property
    def name(self) -> str:
        """The error number's name ("" when 0, "unknown error N" for undocumented numbers)."""
        if self.code == 0:
            return ""
        return STATUS_ERROR_NAMES.get(self.code, f"unknown error {self.code}")

    def __bool__(self) -> bool:
        return self.alert or self.code != 0

    def __str__(self) -> str:
        parts = [self.name] if self.code else []
        if self.alert:
            parts.append("hardware alert")
        return ", ".join(parts) or "no error"


def decode_error(byte: int) -> StatusError:
    """Decode a status packet's error byte."""
    return StatusError.from_byte(byte)


# ---- packets ------------------------------------------------------------------------------
@dataclass(frozen=True)
class InstructionPacket:
    """An instruction packet (host -> servo). ``params`` are unstuffed."""

    id: int
    instruction: int
    params: bytes = b""

    def encode(self) -> bytes:
        """The bytes on the wire (stuffed, with length and CRC)."""
        _check_id(self.id)
        return _frame(self.id, bytes([self.instruction]) + bytes(self.params))


@dataclass(frozen=True)
class StatusPacket:
    """A status packet (servo -> host). ``error`` is the raw error byte, ``params`` unstuffed."""

    id: int
    error: int = 0
    params: bytes = b""

    @property
    def status_error(self) -> StatusError:
        return StatusError.from_byte(self.error)

    @property
    def alert(self) -> bool:
        return bool(self.error & ALERT_BIT)

    @property
    def error_code(self) -> int:
        return self.error & 0x7F

    def encode(self) -> bytes:
        _check_id(self.id, broadcast_ok=False)
        return _frame(self.id, bytes([Instruction.STATUS, self.error]) + bytes(self.params))


@dataclass(frozen=True)
class CorruptFrame:
    """Something that started like a packet but was not one.

    Attributes:
        id: the id byte after the header (may itself be corrupt).
        raw: the bytes of the frame as received (possibly a prefix of it).
        reason: "crc" (complete frame, CRC mismatch), "truncated" (another header began
            before the frame's end: bytes were lost) or "short" (too short a status).
    """

    id: int
    raw: bytes
    reason: str


Packet = InstructionPacket | StatusPacket
Item = InstructionPacket | StatusPacket | CorruptFrame


# ---- instruction builders -----------------------------------------------------------------
def _u16(value: int, what: str) -> bytes:
    if not 0 <= value <= 0xFFFF:
        raise ProtocolError(f"{what} {value} is not in 0..65535")
    return struct.pack("<H", value)


def ping(servo_id: int) -> InstructionPacket:
    """PING: the servo answers with its model number (LE16) and firmware version."""
    return InstructionPacket(servo_id, Instruction.PING)


def read(servo_id: int, address: int, length: int) -> InstructionPacket:
    """READ ``length`` bytes from ``address``."""
    return InstructionPacket(
        servo_id, Instruction.READ, _u16(address, "address") + _u16(length, "length")
    )


def write(servo_id: int, address: int, data: bytes) -> InstructionPacket:
    """WRITE ``data`` at ``address``."""
    if not data:
        raise ProtocolError("write needs at least one data byte")
    return InstructionPacket(servo_id, Instruction.WRITE, _u16(address, "address") + bytes(data))


def reboot(servo_id: int) -> InstructionPacket:
    """REBOOT: restart the servo (clears a hardware error shutdown)."""
    return InstructionPacket(servo_id, Instruction.REBOOT)


def sync_read(address: int, length: int, ids: Sequence[int]) -> InstructionPacket:
    """SYNC_READ (broadcast): each servo in ``ids`` answers, in that order, with ``length``
    bytes from ``address``."""
    if not ids:
        raise ProtocolError("sync read needs at least one id")
    for i in ids:
        _check_id(i, broadcast_ok=False)
    params = _u16(address, "address") + _u16(length, "length") + bytes(ids)
    return InstructionPacket(BROADCAST_ID, Instruction.SYNC_READ, params)


def sync_write(address: int, length: int, data: Mapping[int, bytes]) -> InstructionPacket:
    """SYNC_WRITE (broadcast, no reply): ``data[id]`` (``length`` bytes each) at ``address``."""
    if not data:
        raise ProtocolError("sync write needs at least one id")
    params = bytearray(_u16(address, "address") + _u16(length, "length"))
    for servo_id, chunk in data.items():
        _check_id(servo_id, broadcast_ok=False)
        if len(chunk) != length:
            raise ProtocolError(f"sync write: id {servo_id} has {len(chunk)} bytes, not {length}")
        params.append(servo_id)
        params += chunk
    return InstructionPacket(BROADCAST_ID, Instruction.SYNC_WRITE, bytes(params))


def bulk_read(requests: Iterable[tuple[int, int, int]]) -> InstructionPacket:
    """BULK_READ (broadcast): each ``(id, address, length)`` servo answers in that order."""
    params = bytearray()
    seen = set()
    for servo_id, address, length in requests:
        _check_id(servo_id, broadcast_ok=False)
        if servo_id in seen:
            raise ProtocolError(f"bulk read: id {servo_id} appears twice")
        seen.add(servo_id)
        params.append(servo_id)
        params += _u16(address, "address") + _u16(length, "length")
    if not params:
        raise ProtocolError("bulk read needs at least one request")
    return InstructionPacket(BROADCAST_ID, Instruction.BULK_READ, bytes(params))


# ---- parameter parsers (the servo side, and replies) -----------------------------------------
def parse_read(params: bytes) -> tuple[int, int]:
    """READ params -> (address, length)."""
    if len(params) != 4:
        raise ProtocolError(f"read params have {len(params)} bytes, expected 4")
    address, length = struct.unpack("<HH", params)
    return address, length


def parse_write(params: bytes) -> tuple[int, bytes]:
    """WRITE params -> (address, data)."""
    if len(params) < 3:
        raise ProtocolError(f"write params have {len(params)} bytes, expected at least 3")
    return struct.unpack_from("<H", params)[0], bytes(params[2:])


def parse_sync_read(params: bytes) -> tuple[int, int, list[int]]:
    """SYNC_READ params -> (address, length, ids)."""
    if len(params) < 5:
        raise ProtocolError(f"sync read params have {len(params)} bytes, expected at least 5")
    address, length = struct.unpack_from("<HH", params)
    return address, length, list(params[4:])


def parse_sync_write(params: bytes) -> tuple[int, int, dict[int, bytes]]:
    """SYNC_WRITE params -> (address, length, {id: data})."""
    if len(params) < 4:
        raise ProtocolError(f"sync write params have {len(params)} bytes, expected at least 4")
    address, length = struct.unpack_from("<HH", params)
    rest = params[4:]
    step = 1 + length
    if length == 0 or len(rest) % step:
        raise ProtocolError(f"sync write: {len(rest)} data bytes are not a multiple of {step}")
    return (
        address,
        length,
        {rest[i]: bytes(rest[i + 1 : i + step]) for i in range(0, len(rest), step)},
    )


def parse_bulk_read(params: bytes) -> list[tuple[int, int, int]]:
    """BULK_READ params -> [(id, address, length), ...]."""
    if not params or len(params) % 5:
        raise ProtocolError(f"bulk read params have {len(params)} bytes, not a multiple of 5")
    return [
        (params[i], *struct.unpack_from("<HH", params, i + 1)) for i in range(0, len(params), 5)
    ]


def parse_ping_reply(params: bytes) -> tuple[int, int]:
    """PING status params -> (model number, firmware version)."""
    if len(params) != 3:
        raise ProtocolError(f"ping reply has {len(params)} parameter bytes, expected 3")
    return struct.unpack_from("<H", params)[0], params[2]


# ---- streaming decoder --------------------------------------------------------------------
class Decoder:
    """Finds packets in a byte stream fed in arbitrary chunks.

    Garbage between packets is skipped; a complete frame whose CRC fails, or a frame cut short
    by the next header, is reported as a ``CorruptFrame`` and the search resumes one byte after
    its start. Because stuffing keeps the header out of every packet body, a header seen inside
    a candidate's body proves the candidate is not a packet, so garbage that looks like the
    start of a long packet never stalls the valid packets behind it.

    Instruction packets are returned too (the echo of a half-duplex adapter, or the requests an
    emulator answers): the caller keeps what it wants.

    Args:
        max_length: largest LEN accepted; a header with a larger one is garbage.
    """

    def __init__(self, max_length: int = DEFAULT_MAX_LENGTH) -> None:
        self.max_length = max_length
        self._buf = bytearray()
        self.discarded = 0  # bytes skipped as garbage since creation

    @property
    def pending(self) -> int:
        """Bytes held waiting for the rest of a packet."""
        return len(self._buf)

    def reset(self) -> None:
        """Drop everything buffered (e.g. after a timeout)."""
        self.discarded += len(self._buf)
        self._buf.clear()

    def _drop(self, n: int) -> None:
        del self._buf[:n]
        self.discarded += n

    def feed(self, data: bytes) -> list[Item]:
        """Add bytes; return the packets and corrupt frames completed by them, in order."""
        buf = self._buf
        buf += data
        out: list[Item] = []
        while True:
            start = buf.find(HEADER)
            if start < 0:
                # Keep a tail that may be the beginning of a header.
                keep = next((k for k in (3, 2, 1) if buf.endswith(HEADER[:k])), 0)
                self._drop(len(buf) - keep)
                return out
            if start:
                self._drop(start)
            if len(buf) < PREFIX_SIZE:
                return out
            servo_id = buf[4]
            length = buf[5] | (buf[6] << 8)
            if servo_id == 0xFF or not MIN_LENGTH <= length <= self.max_length:
                self._drop(1)  # not a real header: an id or a length no packet has
                continue
            total = PREFIX_SIZE + length
            crc_at = total - 2
            inner = buf.find(HEADER, 1, crc_at)
            if inner >= 0:
                out.append(CorruptFrame(servo_id, bytes(buf[:inner]), "truncated"))
                self._drop(inner)
                continue
            if len(buf) < total:
                return out
            frame = bytes(buf[:total])
            if crc16(frame[:crc_at]) != (frame[crc_at] | (frame[crc_at + 1] << 8)):
                out.append(CorruptFrame(servo_id, frame, "crc"))
                self._drop(1)
                continue
            del buf[:total]
            body = unstuff(frame[PREFIX_SIZE:crc_at])
            if body[0] == Instruction.STATUS:
                if len(body) < 2:
                    out.append(CorruptFrame(servo_id, frame, "short"))
                    continue
                out.append(StatusPacket(servo_id, body[1], bytes(body[2:])))
            else:
                out.append(InstructionPacket(servo_id, body[0], bytes(body[1:])))


def decode_all(data: bytes) -> list[Packet]:
    """Every packet in ``data`` (corrupt frames left out): a convenience for tests and tools."""
    return [p for p in Decoder().feed(data) if not isinstance(p, CorruptFrame)]
