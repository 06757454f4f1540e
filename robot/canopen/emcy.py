"""EMCY (emergency) messages decoded into one clear line.

An EMCY frame (COB-ID 0x80 + node id, CiA 301 section 7.2.7) carries an error code (16 bits,
little-endian), the error register 0x1001 (8 bits) and 5 manufacturer-specific bytes.
Code 0x0000 means "error reset / no error". Pure: no I/O.
"""

from __future__ import annotations

import struct

# Error codes (CiA 301 table "Emergency error codes" and CiA 402-2 annex; the ones a servo
# drive commonly reports). Exact codes first, then classes by mask in ``CLASSES``.
CODES: dict[int, str] = {
    0x0000: "error reset / no error",
    0x1000: "generic error",
    0x2310: "continuous over-current",
    0x2320: "short circuit at outputs",
    0x3110: "mains over-voltage",
    0x3120: "mains under-voltage",
    0x3210: "DC link over-voltage",
    0x3220: "DC link under-voltage",
    0x4210: "excess temperature of the device",
    0x4310: "excess temperature of the drive",
    0x5441: "safe torque off / enable input",
    0x7121: "motor blocked",
    0x7300: "sensor (encoder) error",
    0x7305: "incremental encoder 1 broken",
    0x8110: "CAN overrun (frames lost)",
    0x8120: "CAN in error passive mode",
    0x8130: "life guard or heartbeat error",
    0x8140: "recovered from bus off",
    0x8210: "PDO not processed due to length error",
    0x8250: "RPDO timeout",
    0x8611: "following error",
    0x8612: "reference limit",
    0xFF00: "device specific",
}
# Classes by (mask, value) when the exact code is not listed (CiA 301; as in canopen's emcy.py).
CLASSES: tuple[tuple[int, int, str], ...] = (
    (0xFF00, 0x1000, "generic error"),
    (0xF000, 0x2000, "current"),
    (0xF000, 0x3000, "voltage"),
    (0xF000, 0x4000, "temperature"),
    (0xFF00, 0x5000, "device hardware"),
    (0xF000, 0x6000, "device software"),
    (0xFF00, 0x7000, "additional modules"),
    (0xF000, 0x8000, "monitoring"),
    (0xFF00, 0x9000, "external error"),
    (0xFF00, 0xF000, "additional functions"),
    (0xFF00, 0xFF00, "device specific"),
)
# Error register 0x1001 bits (CiA 301).
REGISTER_BITS: tuple[str, ...] = (
    "generic",
    "current",
    "voltage",
    "temperature",
    "communication",
    "device profile",
    "reserved",
    "manufacturer",
)
FOLLOWING_ERROR = 0x8611
# Register a drive reports with a following error: generic + device profile (our choice for
# the emulated drive; CiA 301 only requires the generic bit).
FOLLOWING_ERROR_REGISTER = 0x21

_EMCY = struct.Struct("<HB5s")


def describe_code(code: int) -> str:
    """Name of an EMCY error code (exact, else its class, else "unknown")."""
    if code in CODES:
        return CODES[code]
    for mask, value, name in CLASSES:
        if code & mask == value:
            return name
    return "unknown error"


def describe_register(register: int) -> str:
    """Names of the bits set in an error register, comma-separated ("none" when 0)."""
    names = [n for bit, n in enumerate(REGISTER_BITS) if register >> bit & 1]
    return ", ".join(names) if names else "none"


def describe(code: int, register: int) -> str:
    """One line, e.g. ``EMCY 0x8611 following error (error register 0x21: generic, device
    profile)``."""
    return (
        f"EMCY 0x{code:04X} {describe_code(code)} "
        f"(error register 0x{register:02X}: {describe_register(register)})"
    )


def pack(code: int, register: int, vendor: bytes = b"") -> bytes:
    """The 8 data bytes of an EMCY frame."""
    return _EMCY.pack(code, register, vendor[:5])


def unpack(data: bytes) -> tuple[int, int, bytes]:
    """(code, register, vendor bytes) from the data of an EMCY frame (short frames padded)."""
    return _EMCY.unpack(bytes(data).ljust(8, b"\0")[:8])
