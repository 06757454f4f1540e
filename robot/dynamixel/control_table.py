"""Control tables as data, and the conversions from raw register values to SI units.

A ``Model`` holds ``name -> Register(address, size, access, unit)`` plus the few facts needed
to convert raw values: steps per position range, speed unit, load unit, voltage unit. Two
models: XL-320 (model number 350, the Poppy Ergo Jr's servo) and XL-330-M288 (model 1200).

Sources (ROBOTIS e-manual, emanual.robotis.com): "XL-320" control table
(docs/en/dxl/x/xl320/) and "XL330-M288-T" control table (docs/en/dxl/x/xl330-m288/). Register
names are the e-manual's in snake_case. Units: positions rad, speeds rad/s, loads a signed
fraction of the maximum torque (or of the current limit), volts, degrees C.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field

import numpy as np

RPM_TO_RAD_S = 2.0 * math.pi / 60.0


class ControlTableError(KeyError):
    """Unknown model or register (one-line message)."""

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0])


@dataclass(frozen=True)
class Register:
    """One control-table entry.

    Attributes:
        address: first byte, 0-based.
        size: bytes (1, 2 or 4), little-endian.
        access: "R" (read only) or "RW".
        unit: what one raw unit means (e.g. "0.29 deg", "0.1 V", "" for plain numbers).
        eeprom: in the EEPROM area (writable only while torque is off).
        signed: two's complement (X-series velocities, currents, positions).
    """

    address: int
    size: int
    access: str
    unit: str = ""
    eeprom: bool = False
    signed: bool = False

    @property
    def end(self) -> int:
        """One past the last byte."""
        return self.address + self.size

    def encode(self, value: int) -> bytes:
        """Raw value -> little-endian bytes; out-of-range values are refused."""
        fmt = {1: "b", 2: "h", 4: "i"}[self.size]
        return struct.pack("<" + (fmt if self.signed else fmt.upper()), int(value))

    def decode(self, data: bytes) -> int:
        """``size`` little-endian bytes -> raw value."""
        return int.from_bytes(data[: self.size], "little", signed=self.signed)


def _table(
    rows: Mapping[str, tuple[int, int, str, str]], ram_start: int, signed: Iterable[str] = ()
) -> dict[str, Register]:
    signed = set(signed)
    return {
        name: Register(a, s, acc, unit, eeprom=a < ram_start, signed=name in signed)
        for name, (a, s, acc, unit) in rows.items()
    }


@dataclass(frozen=True)
class Model:
    """A servo model's control table and unit conversions.

    Attributes:
        name, number: e.g. "XL-320", 350 (the Model Number register's value).
        registers: name -> Register.
        defaults: factory values of the writable and identity registers (for the emulator).
        position_max: largest position value; positions run 0..position_max.
        position_span_rad: angle covered by 0..position_max, rad.
        position_centre: raw value of the zero angle.
        speed_unit: rad/s per raw speed unit.
        load_unit: fraction of the maximum per raw load unit.
        sign_bit: bit of the direction in sign-magnitude speed/load (XL-320: bit 10), or None
            when those registers are two's complement.
        voltage_unit: volts per raw unit.
        hardware_error_bits: bit number -> name in Hardware Error Status.
        roles: what the arm needs -> register name (``position``, ``goal``, ``torque``,
            ``velocity``, ``load``, ``voltage``, ``temperature``, ``hardware_error``,
            ``return_delay``).
    """

    name: str
    number: int
    registers: Mapping[str, Register]
    defaults: Mapping[str, int]
    position_max: int
    position_span_rad: float
    position_centre: int
    speed_unit: float
    load_unit: float
    sign_bit: int | None
    voltage_unit: float
    hardware_error_bits: Mapping[int, str]
    roles: Mapping[str, str] = field(default_factory=dict)

    @property
    def rad_per_step(self) -> float:
        return self.position_span_rad / self.position_max

    @property
    def table_size(self) -> int:
        """Bytes of the control table (one past the last register)."""
        return max(r.end for r in self.registers.values())

    def reg(self, name: str) -> Register:
        """The register called ``name`` (or the register of a role, e.g. "goal")."""
        name = self.roles.get(name, name)
        try:
            return self.registers[name]
        except KeyError:
            raise ControlTableError(f"{self.name} has no register {name!r}") from None

    def block(self, names: Iterable[str]) -> tuple[int, int]:
        """The smallest (address, length) that covers the named registers (or roles)."""
        regs = [self.reg(n) for n in names]
        start = min(r.address for r in regs)
        return start, max(r.end for r in regs) - start

    def extract(self, name: str, block_address: int, data: bytes) -> int:
        """Raw value of register ``name`` from ``data`` read starting at ``block_address``."""
        r = self.reg(name)
        lo = r.address - block_address
        if lo < 0 or lo + r.size > len(data):
            raise ControlTableError(
                f"{self.name} register {name!r} is not inside the block read at "
                f"{block_address} ({len(data)} bytes)"
            )
        return r.decode(data[lo : lo + r.size])

    # ---- conversions (arrays of raw values, shape (n,)) -----------------------------------
    def steps_to_rad(self, steps: np.ndarray) -> np.ndarray:
        """Raw positions -> servo angles, rad (0 at ``position_centre``)."""
        return (np.asarray(steps, dtype=float) - self.position_centre) * self.rad_per_step

    def rad_to_steps(self, rad: np.ndarray) -> np.ndarray:
        """Servo angles, rad -> raw positions, rounded and clipped to 0..position_max."""
        steps = np.rint(np.asarray(rad, dtype=float) / self.rad_per_step + self.position_centre)
        return np.clip(steps, 0, self.position_max).astype(int)

    def _signed(self, raw: np.ndarray) -> np.ndarray:
        raw = np.asarray(raw, dtype=np.int64)
        if self.sign_bit is None:
            return raw
        magnitude = raw & ((1 << self.sign_bit) - 1)
        return np.where(raw & (1 << self.sign_bit), -magnitude, magnitude)

    def _sign_magnitude(self, value: np.ndarray) -> np.ndarray:
        value = np.asarray(value, dtype=np.int64)
        if self.sign_bit is None:
            return value
        limit = (1 << self.sign_bit) - 1
        mag = np.minimum(np.abs(value), limit)
        return np.where(value < 0, mag | (1 << self.sign_bit), mag)

    def speed_to_rad_s(self, raw: np.ndarray) -> np.ndarray:
        """Raw present speed/velocity -> rad/s (positive: increasing position, CCW)."""
        return self._signed(raw) * self.speed_unit

    def rad_s_to_speed(self, rad_s: np.ndarray) -> np.ndarray:
        """rad/s -> raw present speed (for the emulator)."""
        return self._sign_magnitude(np.rint(np.asarray(rad_s, dtype=float) / self.speed_unit))

    def load_to_fraction(self, raw: np.ndarray) -> np.ndarray:
        """Raw present load/current -> signed fraction of the maximum."""
        return self._signed(raw) * self.load_unit

    def fraction_to_load(self, fraction: np.ndarray) -> np.ndarray:
        """Signed fraction of the maximum -> raw present load (for the emulator)."""
        return self._sign_magnitude(np.rint(np.asarray(fraction, dtype=float) / self.load_unit))

    def voltage_to_volts(self, raw: np.ndarray) -> np.ndarray:
        return np.asarray(raw, dtype=float) * self.voltage_unit

    def temperature_to_c(self, raw: np.ndarray) -> np.ndarray:
        """Present temperature is in whole degrees C on both models (e-manual)."""
        return np.asarray(raw, dtype=float)

    def decode_hardware_error(self, value: int) -> list[str]:
        """Hardware Error Status byte -> names of the bits set (unknown bits as "bit N")."""
        return [self.hardware_error_bits.get(b, f"bit {b}") for b in range(8) if value >> b & 1]


# ---- XL-320 (model 350) ---------------------------------------------------------------------
# ROBOTIS e-manual, XL-320 "Control Table of EEPROM Area" (addresses 0..18) and "Control Table
# of RAM Area" (24..52). (address, size, access, unit).
_XL320_ROWS: dict[str, tuple[int, int, str, str]] = {
    "model_number": (0, 2, "R", ""),
    "firmware_version": (2, 1, "R", ""),
    "id": (3, 1, "RW", ""),
    "baud_rate": (4, 1, "RW", "0: 9600, 1: 57600, 2: 115200, 3: 1M bps"),
    "return_delay_time": (5, 1, "RW", "2 us"),
    "cw_angle_limit": (6, 2, "RW", "0.29 deg"),
    "ccw_angle_limit": (8, 2, "RW", "0.29 deg"),
    "control_mode": (11, 1, "RW", "1: wheel, 2: joint"),
    "temperature_limit": (12, 1, "RW", "1 C"),
    "min_voltage_limit": (13, 1, "RW", "0.1 V"),
    "max_voltage_limit": (14, 1, "RW", "0.1 V"),
    "max_torque": (15, 2, "RW", "0.1 %"),
    "status_return_level": (17, 1, "RW", "0: ping only, 1: +read, 2: all"),
    "shutdown": (18, 1, "RW", "bit0 overload, bit1 overheat, bit2 voltage"),
    "torque_enable": (24, 1, "RW", ""),
    "led": (25, 1, "RW", ""),
    "d_gain": (27, 1, "RW", ""),
    "i_gain": (28, 1, "RW", ""),
    "p_gain": (29, 1, "RW", ""),
    "goal_position": (30, 2, "RW", "0.29 deg"),
    "moving_speed": (32, 2, "RW", "0.111 rpm"),
    "torque_limit": (35, 2, "RW", "0.1 %"),
    "present_position": (37, 2, "R", "0.29 deg"),
    "present_speed": (39, 2, "R", "0.111 rpm, bit 10 = CW"),
    "present_load": (41, 2, "R", "0.1 %, bit 10 = CW"),
    "present_voltage": (45, 1, "R", "0.1 V"),
    "present_temperature": (46, 1, "R", "1 C"),
    "registered": (47, 1, "R", ""),
    "moving": (49, 1, "R", ""),
    "hardware_error_status": (50, 1, "R", "bits as shutdown"),
    "punch": (51, 2, "RW", ""),
}

XL320 = Model(
    name="XL-320",
    number=350,  # e-manual "Model Number" default
    registers=_table(_XL320_ROWS, ram_start=24),  # RAM area starts at 24 (e-manual)
    # Factory defaults (e-manual "Initial Value" column). The firmware version is not given
    # there: 29 is a guess for the emulator only.
    defaults={
        "model_number": 350,
        "firmware_version": 29,
        "id": 1,
        "baud_rate": 3,
        "return_delay_time": 250,
        "cw_angle_limit": 0,
        "ccw_angle_limit": 1023,
        "control_mode": 2,
        "temperature_limit": 65,
        "min_voltage_limit": 60,
        "max_voltage_limit": 90,
        "max_torque": 1023,
        "status_return_level": 2,
        "shutdown": 3,
        "torque_enable": 0,
        "led": 0,
        "d_gain": 0,
        "i_gain": 0,
        "p_gain": 32,
        "goal_position": 512,
        "moving_speed": 0,
        "torque_limit": 1023,
        "punch": 32,
    },
    # 0..1023 over 300 deg, centre 512 (e-manual "Goal Position": 0.29 deg per unit).
    position_max=1023,
    position_span_rad=math.radians(300.0),
    position_centre=512,
    speed_unit=0.111 * RPM_TO_RAD_S,  # e-manual "Moving Speed": about 0.111 rpm per unit
    load_unit=0.001,  # e-manual "Present Load": about 0.1 % per unit, bit 10 direction
    sign_bit=10,  # "Present Speed"/"Present Load": 0..1023 CCW, 1024..2047 CW
    voltage_unit=0.1,  # e-manual "Present Voltage": 0.1 V per unit
    # Hardware Error Status (50) uses the bits of Shutdown (18) (ROBOTIS e-manual).
    hardware_error_bits={0: "overload", 1: "overheating", 2: "input voltage"},
    roles={
        "position": "present_position",
        "goal": "goal_position",
        "torque": "torque_enable",
        "velocity": "present_speed",
        "load": "present_load",
        "voltage": "present_voltage",
        "temperature": "present_temperature",
        "hardware_error": "hardware_error_status",
        "return_delay": "return_delay_time",
    },
)

# ---- XL-330-M288 (model 1200) ---------------------------------------------------------------
# ROBOTIS e-manual, XL330-M288-T control table (X-series layout; EEPROM 0..63, RAM from 64).
_XL330_ROWS: dict[str, tuple[int, int, str, str]] = {
    "model_number": (0, 2, "R", ""),
    "model_information": (2, 4, "R", ""),
    "firmware_version": (6, 1, "R", ""),
    "id": (7, 1, "RW", ""),
    "baud_rate": (8, 1, "RW", "0: 9600, 1: 57600, 2: 115200, 3: 1M bps"),
    "return_delay_time": (9, 1, "RW", "2 us"),
    "drive_mode": (10, 1, "RW", "bit0 reverse"),
    "operating_mode": (11, 1, "RW", "3: position"),
    "secondary_id": (12, 1, "RW", ""),
    "protocol_type": (13, 1, "RW", ""),
    "homing_offset": (20, 4, "RW", "0.088 deg"),
    "moving_threshold": (24, 4, "RW", "0.229 rpm"),
    "temperature_limit": (31, 1, "RW", "1 C"),
    "max_voltage_limit": (32, 2, "RW", "0.1 V"),
    "min_voltage_limit": (34, 2, "RW", "0.1 V"),
    "pwm_limit": (36, 2, "RW", "0.113 %"),
    "current_limit": (38, 2, "RW", "1 mA"),
    "velocity_limit": (44, 4, "RW", "0.229 rpm"),
    "max_position_limit": (48, 4, "RW", "0.088 deg"),
    "min_position_limit": (52, 4, "RW", "0.088 deg"),
    "startup_configuration": (60, 1, "RW", ""),
    "pwm_slope": (62, 1, "RW", ""),
    "shutdown": (63, 1, "RW", "bit0 voltage, 2 overheat, 3 encoder, 4 shock, 5 overload"),
    "torque_enable": (64, 1, "RW", ""),
    "led": (65, 1, "RW", ""),
    "status_return_level": (68, 1, "RW", ""),
    "registered_instruction": (69, 1, "R", ""),
    "hardware_error_status": (70, 1, "R", "bits as shutdown"),
    "velocity_i_gain": (76, 2, "RW", ""),
    "velocity_p_gain": (78, 2, "RW", ""),
    "position_d_gain": (80, 2, "RW", ""),
    "position_i_gain": (82, 2, "RW", ""),
    "position_p_gain": (84, 2, "RW", ""),
    "feedforward_2nd_gain": (88, 2, "RW", ""),
    "feedforward_1st_gain": (90, 2, "RW", ""),
    "bus_watchdog": (98, 1, "RW", "20 ms"),
    "goal_pwm": (100, 2, "RW", "0.113 %"),
    "goal_current": (102, 2, "RW", "1 mA"),
    "goal_velocity": (104, 4, "RW", "0.229 rpm"),
    "profile_acceleration": (108, 4, "RW", ""),
    "profile_velocity": (112, 4, "RW", ""),
    "goal_position": (116, 4, "RW", "0.088 deg"),
    "realtime_tick": (120, 2, "R", "1 ms"),
    "moving": (122, 1, "R", ""),
    "moving_status": (123, 1, "R", ""),
    "present_pwm": (124, 2, "R", "0.113 %"),
    "present_current": (126, 2, "R", "1 mA"),
    "present_velocity": (128, 4, "R", "0.229 rpm"),
    "present_position": (132, 4, "R", "0.088 deg"),
    "velocity_trajectory": (136, 4, "R", ""),
    "position_trajectory": (140, 4, "R", ""),
    "present_input_voltage": (144, 2, "R", "0.1 V"),
    "present_temperature": (146, 1, "R", "1 C"),
}
_XL330_SIGNED = (
    "homing_offset",
    "goal_pwm",
    "goal_current",
    "goal_velocity",
    "goal_position",
    "present_pwm",
    "present_current",
    "present_velocity",
    "present_position",
    "velocity_trajectory",
    "position_trajectory",
)

XL330_M288 = Model(
    name="XL-330-M288",
    number=1200,  # e-manual "Model Number" default
    registers=_table(_XL330_ROWS, ram_start=64, signed=_XL330_SIGNED),
    # Factory defaults (e-manual "Default Value"); firmware 46 is a guess for the emulator.
    defaults={
        "model_number": 1200,
        "firmware_version": 46,
        "id": 1,
        "baud_rate": 1,
        "return_delay_time": 250,
        "drive_mode": 0,
        "operating_mode": 3,
        "temperature_limit": 70,
        "max_voltage_limit": 70,
        "min_voltage_limit": 35,
        "pwm_limit": 885,
        "current_limit": 1750,
        "velocity_limit": 445,
        "max_position_limit": 4095,
        "min_position_limit": 0,
        "shutdown": 52,
        "status_return_level": 2,
        "goal_position": 2048,
    },
    # 4096 steps per turn (0.088 deg per unit), centre 2048 (e-manual "Present Position").
    position_max=4095,
    position_span_rad=2.0 * math.pi * 4095 / 4096,
    position_centre=2048,
    speed_unit=0.229 * RPM_TO_RAD_S,  # e-manual "Present Velocity": 0.229 rpm per unit
    # e-manual "Present Current": 1 mA per unit; normalised by the default Current Limit
    # (1750 mA) to get a load fraction. The normalisation is our choice, not ROBOTIS'.
    load_unit=1.0 / 1750.0,
    sign_bit=None,
    voltage_unit=0.1,  # e-manual "Present Input Voltage": 0.1 V per unit
    # e-manual X-series "Hardware Error Status" / "Shutdown" bits.
    hardware_error_bits={
        0: "input voltage",
        2: "overheating",
        3: "motor encoder",
        4: "electrical shock",
        5: "overload",
    },
    roles={
        "position": "present_position",
        "goal": "goal_position",
        "torque": "torque_enable",
        "velocity": "present_velocity",
        "load": "present_current",
        "voltage": "present_input_voltage",
        "temperature": "present_temperature",
        "hardware_error": "hardware_error_status",
        "return_delay": "return_delay_time",
    },
)

MODELS: dict[int, Model] = {XL320.number: XL320, XL330_M288.number: XL330_M288}


def model_by_name(name: str | int) -> Model:
    """A model by name ("XL-320", "xl320", "XL-330-M288") or by model number (350, 1200)."""
    if isinstance(name, int) or str(name).isdigit():
        model = MODELS.get(int(name))
        if model is None:
            known = ", ".join(f"{m.number} ({m.name})" for m in MODELS.values())
            raise ControlTableError(f"unknown Dynamixel model number {name}; known: {known}")
        return model
    key = str(name).lower().replace("-", "").replace("_", "")
    for m in MODELS.values():
        norm = m.name.lower().replace("-", "")
        if key in (norm, norm + "t"):  # "XL330-M288-T" is the e-manual's full name
            return m
    known = ", ".join(m.name for m in MODELS.values())
    raise ControlTableError(f"unknown Dynamixel model {name!r}; known: {known}")
