"""``DynamixelArm``: the ``robot.Arm`` interface on Dynamixel Protocol 2.0 servos (pyserial).

Every ``read()`` is one SYNC_READ of present position and speed; every ``slow_every``-th read
is a wider SYNC_READ that adds load, voltage and temperature (cached in between). ``command``
is one SYNC_WRITE of goal positions; torque on/off is one SYNC_WRITE checked by a SYNC_READ.

Joint angles versus servo angles, per joint ``j`` (rad):

    servo_angle = direction[j] * joint_angle + offset[j]
    joint_angle = direction[j] * (servo_angle - offset[j])

where ``servo_angle`` is 0 at the servo's centre position (512 on an XL-320). Directions are
+1/-1 (the Poppy configuration's "direct"/"indirect"); offsets come from the joint calibration.
Whole turns follow ``robot.angles``: a joint angle read is wrapped to (-pi, pi]; a goal is
reckoned from the offset in the servo's own turn, about its centre (a servo counts no turns),
and clipped to the servo's range, never wrapped round to its other end.

Safety: clamping, the watchdog and torque-off on disconnect are in ``robot.Arm``. Here, a
servo's hardware alert (overload, overheating, voltage) turns every servo's torque off and
raises ``SafetyStop``. For a run, also wrap the control loop in
``robot.signals.torque_off_on_signals`` so that Ctrl-C or SIGTERM cuts torque at once::

    with DynamixelArm("/dev/ttyUSB0") as arm, torque_off_on_signals(arm):
        arm.set_torque(True)
        ...  # control loop
"""

from __future__ import annotations

import logging
from collections.abc import Sequence

import numpy as np

from robot.angles import anchor, joint_angle, raw_angle
from robot.arm import Arm, JointState, RecoveryPolicy
from robot.dynamixel import protocol as proto
from robot.dynamixel.bus import (
    DEFAULT_BAUD,
    DEFAULT_LATENCY_S,
    DEFAULT_RETRIES,
    DynamixelBus,
    HardwareAlertError,
    NoStatusError,
    SerialLike,
)
from robot.dynamixel.control_table import MODELS, Model, model_by_name
from robot.errors import BusError, SafetyStop
from robot.spec import ArmSpec, ergo_jr_spec, joint_mounting
from robot.torque_guardian import EmergencyPayload, serial_path
from robot.watchdog import Watchdog

log = logging.getLogger(__name__)

# Loads and temperatures change slowly (thermal time constants of seconds; the watchdog holds
# for 2 s): read them on every 10th read only (guess; 4 Hz at a 40 Hz control rate).
DEFAULT_SLOW_EVERY = 10
# Return delay time written at connect, us: 0 as recommended for a fast bus
# (ROBOTIS e-manual: default 250 x 2 us = 500 us per servo).
DEFAULT_RETURN_DELAY_US = 0


class DynamixelArm(Arm):
    """An arm of Dynamixel servos on one serial bus.

    Args:
        port: serial device or pyserial URL (e.g. ``/dev/ttyUSB0``, a pty of the emulator).
        baud: bit/s.
        spec: joints, limits and servo ids (default: the Ergo Jr, ids 1..6).
        model: servo model name or number (every servo must be that model).
        directions: +1/-1 per joint, shape (n,) (default all +1).
        offsets: servo angle at joint zero per joint, shape (n,), rad (default all 0).
        watchdog: load/temperature watchdog (default thresholds if None).
        slow_every: read loads and temperatures every this many reads (1: every read).
        return_delay_us: write this Return Delay Time at connect (torque must be off, it is an
            EEPROM register); None leaves the servos as they are.
        retries, latency_s: passed to the ``DynamixelBus``.
        connection: an open serial-like object instead of opening ``port`` (tests). Such an
            arm cannot reconnect after a lost link (nothing to reopen): it stops instead.
        recovery: reconnection policy after a lost link (see ``robot.arm.RecoveryPolicy``).
    """

    def __init__(
        self,
        port: str,
        baud: int = DEFAULT_BAUD,
        spec: ArmSpec | None = None,
        model: str | int = "XL-320",
        directions: Sequence[float] | None = None,
        offsets: Sequence[float] | None = None,
        watchdog: Watchdog | None = None,
        slow_every: int = DEFAULT_SLOW_EVERY,
        return_delay_us: int | None = DEFAULT_RETURN_DELAY_US,
        retries: int = DEFAULT_RETRIES,
        latency_s: float = DEFAULT_LATENCY_S,
        connection: SerialLike | None = None,
        recovery: RecoveryPolicy | None = None,
    ) -> None:
        super().__init__(spec or ergo_jr_spec(), watchdog, recovery)
        n = self.spec.n
        self.model: Model = model_by_name(model)
        self.ids = self.spec.ids
        if len(set(self.ids)) != n:
            raise ValueError(f"servo ids must be distinct, got {self.ids}")
        self.directions, self.offsets = joint_mounting(n, directions, offsets)
        self._servo_offsets = anchor(self.offsets, 0.0)  # in the servo's turn (robot.angles)
        if slow_every < 1:
            raise ValueError(f"slow_every must be >= 1, got {slow_every}")
        if return_delay_us is not None and not 0 <= return_delay_us <= 508:
            raise ValueError(
                f"return_delay_us must be in 0..508 (2 us steps), got {return_delay_us}"
            )
        self.slow_every = slow_every
        self.return_delay_us = return_delay_us
        self.bus = DynamixelBus(
            port,
            baud,
            retries=retries,
            latency_s=latency_s,
            models=dict.fromkeys(self.ids, self.model),
            connection=connection,
        )
        m = self.model
        self._fast = m.block(["position", "velocity"])
        self._slow = m.block(["position", "velocity", "load", "voltage", "temperature"])
        self._reopenable = connection is None
        self._emergency: EmergencyPayload | None = None
        self._reads = 0
        self._loads = np.full(n, np.nan)
        self._temperatures = np.full(n, np.nan)
        self._voltages = np.full(n, np.nan)

    # ---- conversions -------------------------------------------------------------------------
    def joint_to_steps(self, q: np.ndarray) -> np.ndarray:
        """Joint angles, shape (n,), rad -> raw goal positions, shape (n,) (clipped to the
        servo's range)."""
        return self.model.rad_to_steps(raw_angle(q, self._servo_offsets, self.directions))

    def steps_to_joint(self, steps: np.ndarray) -> np.ndarray:
        """Raw positions, shape (n,) -> joint angles in (-pi, pi], shape (n,), rad."""
        return joint_angle(self.model.steps_to_rad(steps), self.offsets, self.directions)

    @property
    def position_resolution(self) -> np.ndarray:
        """One position unit per joint, shape (n,), rad (XL-320: 300 deg / 1023, e-manual)."""
        return np.full(self.spec.n, self.model.rad_per_step)

    # ---- hooks -------------------------------------------------------------------------------
    def _connect(self) -> None:
        self.bus.open()
        try:
            self._check_servos()
            torque = self._read_torque()
            self._torque = bool(torque.all())
            self._configure_return_delay(torque.any())
        except BaseException:
            self.bus.close()
            raise
        self._reads = 0

    def _check_servos(self) -> None:
        found: dict[int, int] = {}
        missing: list[int] = []
        for sid in self.ids:
            try:
                found[sid] = self.bus.ping(sid).model_number
            except NoStatusError:
                missing.append(sid)
        where = f"on {self.bus.port} at {self.bus.baud} baud"
        if missing and not found:
            raise BusError(
                f"no servo answered {where} (wrong port or baud rate? servos unpowered?)"
            )
        if missing:
            raise BusError(f"servo(s) {', '.join(map(str, missing))} did not answer {where}")
        wrong = {sid: num for sid, num in found.items() if num != self.model.number}
        if wrong:
            sid, num = next(iter(wrong.items()))
            name = MODELS[num].name if num in MODELS else "unknown"
            raise BusError(
                f"servo {sid} {where} is model {num} ({name}), expected {self.model.number} "
                f"({self.model.name})"
            )

    def _read_torque(self) -> np.ndarray:
        reg = self.model.reg("torque")
        data = self.bus.sync_read(reg.address, reg.size, self.ids)
        return np.array([reg.decode(data[i]) == 1 for i in self.ids])

    def _configure_return_delay(self, torque_on: bool) -> None:
        reg = self.model.reg("return_delay")
        data = self.bus.sync_read(reg.address, reg.size, self.ids)
        current = max(reg.decode(data[i]) for i in self.ids)
        wanted = None if self.return_delay_us is None else self.return_delay_us // 2
        if wanted is not None and current != wanted:
            if torque_on:
                log.warning(
                    "return delay left at %d us: torque is on and it is an EEPROM register",
                    2 * current,
                )
            else:
                for sid in self.ids:  # EEPROM: only when different, to spare its write cycles
                    if reg.decode(data[sid]) != wanted:
                        self.bus.write(sid, reg.address, reg.encode(wanted))
                current = wanted
        self.bus.return_delay_s = 2e-6 * current

    def _disconnect(self) -> None:
        self.bus.close()

    @property
    def can_reconnect(self) -> bool:
        """True when the port is opened by name (not given as ``connection=``)."""
        return self._reopenable

    def _backend_counts(self) -> dict[str, float]:
        """The bus's counters (calls, retries, timeouts, CRC errors, servo errors, alerts)."""
        return {f"bus_{k}": v for k, v in self.bus.counters.as_dict().items()}

    def _read(self) -> JointState:
        slow = self._reads % self.slow_every == 0
        self._reads += 1
        address, length = self._slow if slow else self._fast
        try:
            data = self.bus.sync_read(address, length, self.ids)
        except HardwareAlertError as exc:
            self._emergency_torque_off()
            raise SafetyStop(f"safety stop: {exc}; torque off") from exc
        # the reading's time: when its request left the host, at which each servo samples
        # what it reports (the request's wire time: 0.2 ms for 20 bytes at 1 Mbps), not
        # when the replies came back, which adds the adapter's latency timer (up to 16 ms on an
        # FTDI, docs/facts.md) and the host's scheduling
        stamp = self.bus.last_sent_at
        m = self.model

        def column(role: str) -> np.ndarray:
            return np.array([m.extract(role, address, data[i]) for i in self.ids])

        positions = self.steps_to_joint(column("position"))
        velocities = self.directions * m.speed_to_rad_s(column("velocity"))
        if slow:
            self._loads = self.directions * m.load_to_fraction(column("load"))
            self._temperatures = m.temperature_to_c(column("temperature"))
            self._voltages = m.voltage_to_volts(column("voltage"))
        return JointState(
            positions=positions,
            velocities=velocities,
            loads=self._loads.copy(),
            temperatures=self._temperatures.copy(),
            errors=np.zeros(self.spec.n, dtype=int),
            timestamp=stamp,
        )

    @property
    def voltages(self) -> np.ndarray:
        """Last supply voltages read, shape (n,), V (NaN before the first slow read)."""
        return self._voltages.copy()

    def _send(self, positions: np.ndarray) -> None:
        reg = self.model.reg("goal")
        steps = self.joint_to_steps(positions)
        data = {sid: reg.encode(int(s)) for sid, s in zip(self.ids, steps, strict=True)}
        self.bus.sync_write(reg.address, reg.size, data)

    def _set_torque(self, enabled: bool) -> None:
        """SYNC_WRITE torque enable, then check it took (a sync write has no reply); one resend
        before giving up with ``BusError``."""
        reg = self.model.reg("torque")
        data = dict.fromkeys(self.ids, reg.encode(int(enabled)))
        for _ in range(2):
            self.bus.sync_write(reg.address, reg.size, data)
            if not enabled:
                self._torque_off_sent()
            try:
                state = self._read_torque()
            except HardwareAlertError as exc:
                if enabled:  # a servo shut down as it was switched on: switch all off
                    self._emergency_torque_off()
                    raise SafetyStop(f"safety stop: {exc}; torque off") from exc
                state = self._read_torque_ignoring_alerts()
            if np.all(state == enabled):
                return
        off = [sid for sid, s in zip(self.ids, state, strict=True) if s != enabled]
        word = "on" if enabled else "off"
        raise BusError(f"servo(s) {', '.join(map(str, off))} did not turn torque {word}")

    def emergency_payload(self) -> EmergencyPayload | None:
        """A broadcast WRITE of Torque Enable = 0 (no status reply: e-manual, Protocol 2.0),
        for a guardian process to write to the port by its path; None for an arm given a
        ``connection`` or a pyserial URL."""
        path = serial_path(self.bus.port) if self._reopenable else None
        if path is None:
            return None
        if self._emergency is None:
            reg = self.model.reg("torque")
            packet = proto.write(proto.BROADCAST_ID, reg.address, reg.encode(0))
            self._emergency = EmergencyPayload(path, packet.encode())
        return self._emergency

    def _emergency_torque_off(self) -> None:
        """Torque off now, from any thread: a call in progress elsewhere gives up first
        (``DynamixelBus.preempt``), so a signal never waits for its timeouts and retries."""
        with self.bus.preempt():
            super()._emergency_torque_off()

    def _read_torque_ignoring_alerts(self) -> np.ndarray:
        reg = self.model.reg("torque")
        return np.array(
            [
                reg.decode(self.bus.read(sid, reg.address, reg.size, check_alert=False)) == 1
                for sid in self.ids
            ]
        )
