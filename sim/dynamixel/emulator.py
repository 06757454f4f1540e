"""Servos that answer Dynamixel Protocol 2.0 packets, backed by the twin: the packet logic of
``ergo twin serve --bus dynamixel``, usable in-process (no I/O here but sleeping in
``EmulatedSerial``).

Six XL-320 at ids 1..6 by default (id k drives twin joint m{k}). What a real servo does and
this one does too (ROBOTIS e-manual, Protocol 2.0 and XL-320 pages):
- torque enable -> the twin joint's actuator on/off; goal position -> the actuator's target;
  present position, speed and load computed from the physics on every read;
- WRITE to EEPROM (addresses below 24) while torque is on -> access error; to a read-only
  register -> access error; outside the table -> data range error; half a register -> data
  length error; a goal outside 0..1023 or the angle limits -> data limit error;
- return delay time honoured (the reply is scheduled that late; in a sync read each servo
  answers after the previous one plus its own delay); status return level honoured;
- broadcast: no reply, except to PING, SYNC_READ and BULK_READ;
- a complete packet for one of our ids whose CRC fails -> CRC error status.

Fault injection (``FaultConfig``): replies dropped, corrupted or late at a rate, an extra
delay, a servo that stops answering (remove it from ``servos``), and
an "overload servo" that, after its torque has been on for a while, sets the overload bit of
its Hardware Error Status, raises the alert bit in every status and shuts its torque off
(the XL-320's Shutdown behaviour) until REBOOT.
"""

from __future__ import annotations

import contextlib
import random
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from robot.angles import anchor, joint_angle_in_turn, raw_angle
from robot.dynamixel import protocol as proto
from robot.dynamixel.control_table import XL320, Model
from robot.spec import joint_mounting

if TYPE_CHECKING:
    from sim.twin import Twin

# Reply scheduled by the emulator: (seconds after the request's last byte, bytes on the wire).
Reply = tuple[float, bytes]

# Present voltage the emulated servos report: the XL-320's recommended 7.4 V (ROBOTIS
# datasheet), in the register's 0.1 V unit.
NOMINAL_VOLTAGE_RAW = 74
# Present temperature reported, C: room temperature; the twin has no thermal model (guess).
ROOM_TEMPERATURE_C = 25
# |velocity| above which "moving" reads 1, rad/s. Guess: about 1 deg/s.
MOVING_THRESHOLD_RAD_S = 0.02
# Torque-on time before the injected overload trips when none is given, s (guess: long
# enough to see the arm move first).
DEFAULT_OVERLOAD_AFTER_S = 2.0
# How late a "late" status packet comes, s: past the bus's timeout with its default 20 ms of
# latency slack (robot.dynamixel.bus.DEFAULT_LATENCY_S), so the host sees a timeout (guess).
DEFAULT_LATE_S = 0.03


@dataclass
class FaultConfig:
    """Faults to inject.

    Attributes:
        drop_rate: fraction of status packets never sent, 0..1.
        corrupt_rate: fraction of status packets sent with one byte flipped, 0..1.
        extra_delay_s: added before every reply, s.
        late_rate: fraction of status packets sent ``late_s`` late, 0..1.
        late_s: how late those are, s.
        overload_servo: id that raises an overload alert, or None.
        overload_after_s: torque-on time (twin time, or wall time without a twin) before it
            trips, s.
        seed: random seed of the drop/corrupt draws.
    """

    drop_rate: float = 0.0
    corrupt_rate: float = 0.0
    extra_delay_s: float = 0.0
    late_rate: float = 0.0
    late_s: float = DEFAULT_LATE_S
    overload_servo: int | None = None
    overload_after_s: float = DEFAULT_OVERLOAD_AFTER_S
    seed: int = 0

    def __post_init__(self) -> None:
        for name in ("drop_rate", "corrupt_rate", "late_rate"):
            value = getattr(self, name)
            if not 0.0 <= value <= 1.0:
                raise ValueError(f"{name} must be in [0, 1], got {value}")
        if self.extra_delay_s < 0 or self.overload_after_s < 0 or self.late_s < 0:
            raise ValueError("delays must be >= 0")


class EmulatedServo:
    """One servo's control table (raw bytes) and fault state.

    Args:
        servo_id: bus id.
        joint: index of the twin joint it drives (0..5).
        model: control table.
    """

    def __init__(self, servo_id: int, joint: int, model: Model = XL320) -> None:
        self.model = model
        self.joint = joint
        self.table = bytearray(model.table_size)
        for name, value in model.defaults.items():
            self.poke(name, value)
        self.poke("id", servo_id)
        self.poke("position", self.peek("goal"))  # at rest on its goal until physics says
        self.hardware_error = 0
        self.torque_on_since: float | None = None
        # wall time (time.monotonic, system-wide) of the last torque-off write, for measuring
        # how fast a host cuts torque
        self.torque_off_at: float | None = None

    @property
    def id(self) -> int:
        return self.peek("id")

    def peek(self, name: str) -> int:
        r = self.model.reg(name)
        return r.decode(bytes(self.table[r.address : r.end]))

    def poke(self, name: str, value: int) -> None:
        r = self.model.reg(name)
        self.table[r.address : r.end] = r.encode(value)

    @property
    def torque(self) -> bool:
        return self.peek("torque") == 1

    @property
    def return_delay_s(self) -> float:
        return self.peek("return_delay") * 2e-6  # 2 us per unit (e-manual)


def _write_error(servo: EmulatedServo, address: int, data: bytes) -> int:
    """The error number a WRITE of ``data`` at ``address`` gets (0: accepted)."""
    model = servo.model
    end = address + len(data)
    if end > model.table_size:
        return proto.DATA_RANGE_ERROR
    touched = [r for r in model.registers.values() if r.address < end and address < r.end]
    covered = sum(r.size for r in touched)
    if not touched or any(r.address < address or r.end > end for r in touched):
        return proto.DATA_LENGTH_ERROR  # half a register, or only gaps
    if covered != len(data):
        return proto.ACCESS_ERROR  # writes over undefined (reserved) addresses
    if any(r.access != "RW" for r in touched):
        return proto.ACCESS_ERROR
    if servo.torque and any(r.eeprom for r in touched):
        return proto.ACCESS_ERROR  # EEPROM is locked while torque is on (e-manual)
    goal = model.reg("goal")
    if goal.address >= address and goal.end <= end:
        value = goal.decode(data[goal.address - address :])
        lo, hi = 0, model.position_max
        if "cw_angle_limit" in model.registers:
            lo, hi = servo.peek("cw_angle_limit"), servo.peek("ccw_angle_limit")
        if not lo <= value <= hi:
            return proto.DATA_LIMIT_ERROR
    return 0


class DynamixelEmulator:
    """Answers instruction packets as a chain of servos on the twin.

    Args:
        twin: the twin whose joints the servos drive (None: static registers, for codec and
            bus tests without physics).
        ids: servo ids; id ``ids[k]`` drives twin joint k.
        model: control table of every servo.
        faults: faults to inject.
        now: clock for the overload timer without a twin (default ``time.monotonic``).
        start_torque: servos power up with torque on, holding the twin's pose (a real XL-320
            powers up with torque off, the default: the arm then sags under gravity).
        directions, offsets: how each servo is mounted on its joint, shape (6,) each (default
            +1 and 0): ``servo_angle = direction * joint_angle + offset`` (rad; the convention
            of ``robot.dynamixel.arm``), so the raw positions a host reads and writes are the
            servo's, not the joint's (a stand-in rig's hidden mounting, ``sim.standin``).
    """

    def __init__(
        self,
        twin: Twin | None = None,
        ids: Sequence[int] = (1, 2, 3, 4, 5, 6),
        model: Model = XL320,
        faults: FaultConfig | None = None,
        now: Callable[[], float] | None = None,
        start_torque: bool = False,
        directions: Sequence[float] | None = None,
        offsets: Sequence[float] | None = None,
    ) -> None:
        self.twin = twin
        n = len(ids)
        self.directions, self.offsets = joint_mounting(n, directions, offsets)
        # a servo counts no turns: its angle is about its centre (robot.angles)
        self._servo_offsets = anchor(self.offsets, 0.0)
        self.model = model
        self.faults = faults or FaultConfig()
        self.servos: dict[int, EmulatedServo] = {
            sid: EmulatedServo(sid, k, model) for k, sid in enumerate(ids)
        }
        self._rng = random.Random(self.faults.seed)
        self._decoder = proto.Decoder()
        self._now = now or time.monotonic
        self.lock = threading.Lock()
        self.handled = 0  # instruction packets handled
        if twin is not None:
            with twin.lock:
                targets = twin.joint_positions()
            for servo in self.servos.values():
                steps = int(model.rad_to_steps(self._servo_angle(servo, targets[servo.joint])))
                servo.poke("goal", steps)
                self._apply_goal(servo)
        if start_torque:
            for servo in self.servos.values():
                servo.poke("torque", 1)
                servo.torque_on_since = self._time()
        self._apply_torque()

    # ---- entry points ------------------------------------------------------------------------
    def handle_bytes(self, data: bytes) -> list[Reply]:
        """Feed received bytes; return the replies due, each with its delay after the request.
        The packets are answered at the twin's present (``_at_present``)."""
        with self.lock:
            items = self._decoder.feed(data)
            if not items:
                return []
            replies: list[Reply] = []
            with self._at_present():
                for item in items:
                    replies += self._handle_item(item)
            return replies

    def handle(self, packet: proto.InstructionPacket) -> list[Reply]:
        """Answer one instruction packet (at the twin's present)."""
        with self.lock, self._at_present():
            return self._handle_item(packet)

    @contextlib.contextmanager
    def _at_present(self) -> Iterator[None]:
        """Hold the twin's lock, its physics caught up to the wall time (``Twin.catch_up``:
        a no-op unless a real-time loop paces it), as a servo answers with its state at the
        moment the request arrives and acts on a goal at once."""
        if self.twin is None:
            yield
            return
        with self.twin.lock:
            self.twin.catch_up()
            yield

    def torque_states(self) -> dict[int, bool]:
        """id -> torque enabled (after any shutdown)."""
        with self.lock:
            self._update_faults()
            return {sid: s.torque for sid, s in self.servos.items()}

    # ---- dispatch ----------------------------------------------------------------------------
    def _handle_item(self, item: proto.Item) -> list[Reply]:
        if isinstance(item, proto.CorruptFrame):
            servo = self.servos.get(item.id)
            if item.reason == "crc" and servo is not None:
                return self._schedule([(servo, proto.CRC_ERROR, b"")], level=2)
            return []
        if isinstance(item, proto.StatusPacket):
            return []  # another device's status: not for us
        self.handled += 1
        self._update_faults()
        inst = item.instruction
        broadcast = item.id == proto.BROADCAST_ID
        targets = list(self.servos.values()) if broadcast else [self.servos.get(item.id)]
        if targets == [None]:
            return []
        try:
            if inst == proto.Instruction.PING:
                ping = [(s, 0, self._ping_params(s)) for s in targets]
                return self._schedule(ping, level=0)
            if inst == proto.Instruction.READ:
                return [] if broadcast else self._read(targets[0], *proto.parse_read(item.params))
            if inst == proto.Instruction.WRITE:
                address, data = proto.parse_write(item.params)
                errors = [(s, self._write(s, address, data), b"") for s in targets]
                return [] if broadcast else self._schedule(errors, level=2)
            if inst == proto.Instruction.SYNC_WRITE:
                address, _, chunks = proto.parse_sync_write(item.params)
                for sid, chunk in chunks.items():
                    if sid in self.servos:
                        self._write(self.servos[sid], address, chunk)
                return []
            if inst == proto.Instruction.SYNC_READ:
                address, length, ids = proto.parse_sync_read(item.params)
                return self._multi_read([(i, address, length) for i in ids])
            if inst == proto.Instruction.BULK_READ:
                return self._multi_read(proto.parse_bulk_read(item.params))
            if inst == proto.Instruction.REBOOT:
                for s in targets:
                    self._reboot(s)
                return [] if broadcast else self._schedule([(targets[0], 0, b"")], level=2)
        except proto.ProtocolError:
            if broadcast:
                return []
            return self._schedule([(targets[0], proto.DATA_LENGTH_ERROR, b"")], level=2)
        if broadcast:
            return []
        return self._schedule([(targets[0], proto.INSTRUCTION_ERROR, b"")], level=2)

    def _ping_params(self, servo: EmulatedServo) -> bytes:
        return servo.model.reg("model_number").encode(servo.model.number) + bytes(
            [servo.peek("firmware_version")]
        )

    def _read(self, servo: EmulatedServo, address: int, length: int) -> list[Reply]:
        return self._schedule([self._read_one(servo, address, length)], level=1)

    def _read_one(
        self, servo: EmulatedServo, address: int, length: int
    ) -> tuple[EmulatedServo, int, bytes]:
        if length == 0 or address + length > servo.model.table_size:
            return servo, proto.DATA_RANGE_ERROR, b""
        self._refresh(servo)
        return servo, 0, bytes(servo.table[address : address + length])

    def _multi_read(self, requests: list[tuple[int, int, int]]) -> list[Reply]:
        answers = [
            self._read_one(self.servos[i], address, length)
            for i, address, length in requests
            if i in self.servos
        ]
        return self._schedule(answers, level=1)

    def _schedule(self, answers: list[tuple[EmulatedServo, int, bytes]], level: int) -> list[Reply]:
        """Status packets for ``answers`` (servo, error number, params), each servo answering
        after the previous one plus its return delay; ``level``: the status return level
        needed for a reply (0 ping, 1 reads, 2 everything)."""
        out: list[Reply] = []
        delay = self.faults.extra_delay_s
        for servo, error, params in answers:
            if servo.peek("status_return_level") < level:
                continue
            delay += servo.return_delay_s
            if servo.hardware_error:
                error |= proto.ALERT_BIT
            wire = proto.StatusPacket(servo.id, error, params).encode()
            if self.faults.drop_rate and self._rng.random() < self.faults.drop_rate:
                continue
            if self.faults.corrupt_rate and self._rng.random() < self.faults.corrupt_rate:
                flipped = bytearray(wire)
                flipped[self._rng.randrange(7, len(wire))] ^= 1 << self._rng.randrange(8)
                wire = bytes(flipped)
            late = self.faults.late_rate and self._rng.random() < self.faults.late_rate
            out.append((delay + self.faults.late_s if late else delay, wire))
        return out

    # ---- state changes -----------------------------------------------------------------------
    def _write(self, servo: EmulatedServo, address: int, data: bytes) -> int:
        error = _write_error(servo, address, data)
        if error:
            return error
        torque = servo.model.reg("torque")
        before = servo.torque
        servo.table[address : address + len(data)] = data
        if servo.hardware_error and servo.torque:
            servo.poke("torque", 0)  # after a shutdown only REBOOT re-enables torque (e-manual)
        if servo.torque != before:
            servo.torque_on_since = self._time() if servo.torque else None
            if not servo.torque:
                servo.torque_off_at = time.monotonic()
        if torque.address >= address and torque.end <= address + len(data):
            self._apply_torque()
        goal = servo.model.reg("goal")
        if goal.address < address + len(data) and address < goal.end:
            self._apply_goal(servo)
        if servo.id not in self.servos:  # its ID register was written: it answers as the new id
            self.servos = {s.id: s for s in self.servos.values()}
        return 0

    def _reboot(self, servo: EmulatedServo) -> None:
        model = servo.model
        for name, value in model.defaults.items():
            if not model.reg(name).eeprom:
                servo.poke(name, value)
        servo.hardware_error = 0
        servo.torque_on_since = None
        if self.twin is not None:
            with self.twin.lock:
                q = self.twin.joint_positions()[servo.joint]
            servo.poke("goal", int(model.rad_to_steps(self._servo_angle(servo, q))))
            self._apply_goal(servo)
        self._apply_torque()

    def _time(self) -> float:
        return self.twin.time if self.twin is not None else self._now()

    def _update_faults(self) -> None:
        sid = self.faults.overload_servo
        servo = self.servos.get(sid) if sid is not None else None
        if servo is None or servo.hardware_error or servo.torque_on_since is None:
            return
        if self._time() - servo.torque_on_since < self.faults.overload_after_s:
            return
        bit = next(b for b, n in servo.model.hardware_error_bits.items() if n == "overload")
        servo.hardware_error |= 1 << bit
        if servo.peek("shutdown") >> bit & 1:  # shutdown on overload: torque off
            servo.poke("torque", 0)
            servo.torque_on_since = None
            self._apply_torque()

    # ---- the twin ----------------------------------------------------------------------------
    def _servo_angle(self, servo: EmulatedServo, q: float) -> float:
        """Joint angle (rad) -> the servo's angle (rad) on its mounting."""
        j = servo.joint
        return float(raw_angle(q, self._servo_offsets[j], self.directions[j]))

    def _apply_goal(self, servo: EmulatedServo) -> None:
        if self.twin is None:
            return
        angle = float(servo.model.steps_to_rad(np.array([servo.peek("goal")]))[0])
        j = servo.joint
        q = float(joint_angle_in_turn(angle, self._servo_offsets[j], self.directions[j]))
        with self.twin.lock:
            targets = self.twin.targets()
            targets[servo.joint] = q
            self.twin.set_targets(targets)

    def _apply_torque(self) -> None:
        if self.twin is None:
            return
        mask = np.zeros(6, dtype=bool)
        for s in self.servos.values():
            mask[s.joint] = s.torque
        set_joint_torques(self.twin, mask)

    def _refresh(self, servo: EmulatedServo) -> None:
        """Present position, speed, load, voltage, temperature, moving, hardware error."""
        model = servo.model
        if self.twin is not None:
            with self.twin.lock:
                j = servo.joint
                q = self.twin.joint_positions_now()[j]  # sampled now, between physics steps
                v = self.twin.joint_velocities()[j]
                load = self.twin.joint_torques()[j] / self.twin.max_torques()[j]
            d = self.directions[j]
            servo.poke("position", int(model.rad_to_steps(self._servo_angle(servo, q))))
            servo.poke("velocity", int(model.rad_s_to_speed(d * v)))
            servo.poke("load", int(model.fraction_to_load(d * load)))
            servo.poke("moving", int(abs(v) > MOVING_THRESHOLD_RAD_S))
        elif servo.torque:
            servo.poke("position", servo.peek("goal"))  # no physics: an ideal, instant servo
        servo.poke("voltage", NOMINAL_VOLTAGE_RAW)  # 0.1 V units on both models
        servo.poke("temperature", ROOM_TEMPERATURE_C)
        servo.poke("hardware_error", servo.hardware_error)


def set_joint_torques(twin: Twin, mask: np.ndarray) -> None:
    """Servo power per joint: ``mask`` shape (6,), True = torque on."""
    twin.set_joint_torque(mask)


class EmulatedSerial:
    """A pyserial-like in-process connection to a ``DynamixelEmulator``: what is written is
    answered after the replies' delays (sleeping in ``read``). For ``DynamixelBus(...,
    connection=EmulatedSerial(emulator))``.

    Args:
        emulator: who answers.
        timeout: how long ``read`` waits for a byte when none is due, s.
        echo: also return what was written first, as a half-duplex adapter does.
    """

    def __init__(self, emulator: DynamixelEmulator, timeout: float = 0.001, echo: bool = False):
        self.emulator = emulator
        self.timeout = timeout
        self.echo = echo
        self._due: list[tuple[float, bytes]] = []
        self.is_open = True
        self.written = bytearray()

    def write(self, data: bytes) -> int:
        now = time.monotonic()
        self.written += data
        if self.echo:
            self._due.append((now, bytes(data)))
        # one wire: a reply never overtakes an earlier one (a late reply delays those behind)
        last = max((t for t, _ in self._due), default=now)
        for d, wire in self.emulator.handle_bytes(bytes(data)):
            last = max(last, now + d)
            self._due.append((last, wire))
        return len(data)

    def _ready(self) -> bytes:
        now = time.monotonic()
        out = b"".join(w for t, w in self._due if t <= now)
        self._due = [(t, w) for t, w in self._due if t > now]
        return out

    @property
    def in_waiting(self) -> int:
        now = time.monotonic()
        return sum(len(w) for t, w in self._due if t <= now)

    def read(self, size: int = 1) -> bytes:
        out = self._ready()
        if not out:
            wait = self.timeout
            if self._due:
                wait = min(wait, max(0.0, self._due[0][0] - time.monotonic()))
            time.sleep(wait)
            out = self._ready()
        return out  # may exceed ``size``: the bus reads what is there

    def flush(self) -> None:
        pass

    def reset_input_buffer(self) -> None:
        """Drop what has arrived (as ``tcflush``): a reply still on its way comes later."""
        now = time.monotonic()
        self._due = [(t, w) for t, w in self._due if t > now]

    def close(self) -> None:
        self.is_open = False
