"""EMCY (emergency) messages decoded into one clear line.

An EMCY frame (COB-ID 0x80 + node id, CiA 301 section 7.2.7) carries an error code (16 bits,
little-endian), the error register 0x1001 (8 bits) and 5 manufacturer-specific bytes.
Code 0x0000 means "error reset / no error". Pure: no I/O.
"""

from __future__ import annotations

import struct

# Error codes by their own name. "301": CiA 301 (section "Emergency object", table "Emergency
# error codes"), the classes and the communication codes; the rest are CiA 402-2's drive codes
# (its annex "Error codes", the table of IEC 61800-7-201, which drive manuals reproduce).
# Some names are shortened or given the group they belong to ("sensor: speed" for 0x7310).
CODES: dict[int, str] = {
    0x0000: "error reset / no error",  # 301
    0x1000: "generic error",  # 301
    0x2110: "short circuit or earth leakage (input)",
    0x2120: "earth leakage (input)",
    0x2130: "short circuit (input)",
    0x2310: "continuous over-current",
    0x2311: "continuous over-current no 1",
    0x2312: "continuous over-current no 2",
    0x2320: "short circuit at outputs",  # short circuit or earth leakage, motor side
    0x2330: "earth leakage (motor side)",
    0x2340: "short circuit (motor side)",
    0x3110: "mains over-voltage",
    0x3120: "mains under-voltage",
    0x3130: "phase failure",
    0x3140: "mains frequency",
    0x3210: "DC link over-voltage",
    0x3220: "DC link under-voltage",
    0x3230: "load error",
    0x3310: "output over-voltage",
    0x3320: "armature circuit",
    0x3330: "field circuit",
    0x4110: "excess ambient temperature",
    0x4120: "too low ambient temperature",
    0x4210: "excess temperature of the device",
    0x4220: "too low temperature of the device",
    0x4310: "excess temperature of the drive",
    0x4320: "too low temperature of the drive",
    0x4410: "excess temperature of the supply",
    0x4420: "too low temperature of the supply",
    0x5110: "supply low voltage",
    0x5210: "measurement circuit",
    0x5220: "computing circuit",
    0x5410: "output stages",
    0x5420: "chopper",
    0x5430: "input stages",
    0x5441: "safe torque off / enable input",  # CiA 402-2: contact 1, manufacturer specific
    0x5510: "data storage: working memory",
    0x5520: "data storage: program memory",
    0x5530: "data storage: non-volatile data memory",
    0x6010: "software reset (watchdog)",
    0x6310: "loss of parameters",
    0x6320: "parameter error",
    0x7110: "brake chopper",
    0x7111: "brake chopper failure",
    0x7112: "brake chopper over-current",
    0x7113: "brake chopper protective circuit",
    0x7121: "motor blocked",
    0x7122: "motor error or commutation malfunction",
    0x7123: "motor tilted",
    0x7300: "sensor (encoder) error",
    0x7301: "tacho fault",
    0x7302: "tacho wrong polarity",
    0x7303: "resolver 1 fault",
    0x7304: "resolver 2 fault",
    0x7305: "incremental encoder 1 broken",
    0x7306: "incremental encoder 2 broken",
    0x7307: "incremental encoder 3 broken",
    0x7310: "sensor: speed",
    0x7320: "sensor: position",
    0x7510: "serial interface no 1",
    0x7520: "serial interface no 2",
    0x8110: "CAN overrun (frames lost)",  # 301
    0x8120: "CAN in error passive mode",  # 301
    0x8130: "life guard or heartbeat error",  # 301
    0x8140: "recovered from bus off",  # 301
    0x8150: "CAN-ID collision",  # 301
    0x8210: "PDO not processed due to length error",  # 301
    0x8220: "PDO length exceeded",  # 301
    0x8230: "DAM MPDO not processed, destination object not available",  # 301
    0x8240: "unexpected SYNC data length",  # 301
    0x8250: "RPDO timeout",  # 301
    0x8311: "excess torque",
    0x8312: "difficult start up",
    0x8313: "standstill torque",
    0x8321: "insufficient torque",
    0x8331: "torque fault",
    0x8611: "following error",
    0x8612: "reference limit",
    0xF001: "deceleration",
    0xF002: "sub-synchronous run",
    0xF003: "stroke operation",
    0xF004: "control",
    0xFF00: "device specific",  # 301
}
# Groups (mask 0xFF00) when the exact code is not listed: CiA 402-2's second level, CiA 301's
# for communication and protocol.
GROUPS: dict[int, str] = {
    0x2100: "current, device input side",
    0x2200: "current inside the device",
    0x2300: "current, device output side",
    0x3100: "mains voltage",
    0x3200: "voltage inside the device",  # CiA 402-2: DC link voltage
    0x3300: "output voltage",
    0x4100: "ambient temperature",
    0x4200: "device temperature",
    0x4300: "drive temperature",
    0x4400: "supply temperature",
    0x5100: "supply",
    0x5200: "control",
    0x5300: "operating unit",
    0x5400: "power section",
    0x5500: "data storage",
    0x6100: "internal software",
    0x6200: "user software",
    0x6300: "data set",
    0x7100: "power",
    0x7200: "measurement circuit",
    0x7300: "sensor",
    0x7400: "computation circuit",
    0x7500: "communication",
    0x7600: "data storage",
    0x8100: "communication",  # 301
    0x8200: "protocol error",  # 301
    0x8300: "torque control",
    0x8400: "velocity speed controller",
    0x8500: "position controller",
    0x8600: "positioning controller",
    0x8700: "sync controller",
    0x8800: "winding controller",
    0x8900: "process data monitoring",
    0x8A00: "control",
}
# Classes by (mask, value) when neither the code nor its group is listed (CiA 301: 00xx, 10xx,
# 90xx, F0xx and FFxx are classes of one group; 2xxx to 8xxx whole). The ``canopen`` library's
# own table (its emcy.py) masks 5xxx and 7xxx with 0xFF00, so that e.g. 0x7310 has no name.
CLASSES: tuple[tuple[int, int, str], ...] = (
    (0xFF00, 0x1000, "generic error"),
    (0xF000, 0x2000, "current"),
    (0xF000, 0x3000, "voltage"),
    (0xF000, 0x4000, "temperature"),
    (0xF000, 0x5000, "device hardware"),
    (0xF000, 0x6000, "device software"),
    (0xF000, 0x7000, "additional modules"),
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
    """Name of an EMCY error code (exact, else its group, else its class, else "unknown
    error")."""
    if code in CODES:
        return CODES[code]
    if code & 0xFF00 in GROUPS:
        return GROUPS[code & 0xFF00]
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
