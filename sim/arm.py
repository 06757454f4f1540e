"""``SimArm``: the ``robot.Arm`` interface on the twin, in-process."""

from __future__ import annotations

import numpy as np

from robot.arm import Arm, JointState
from robot.spec import ArmSpec, ergo_jr_spec
from robot.watchdog import Watchdog
from sim.twin import Twin

# The twin does not heat (room temperature, constant) and reports no error flags: one
# read-only array of each, shared by every reading (shape (6,)).
_ROOM_C = np.full(6, 25.0)
_ROOM_C.setflags(write=False)
_NO_ERRORS = np.zeros(6, dtype=int)
_NO_ERRORS.setflags(write=False)


class SimArm(Arm):
    """The twin's arm. Commands become actuator targets; physics advances only when the rig's
    clock steps the twin (never in ``command``). With torque off the joints go limp."""

    def __init__(self, twin: Twin, spec: ArmSpec | None = None, watchdog: Watchdog | None = None):
        super().__init__(spec or ergo_jr_spec(), watchdog)
        self.twin = twin
        self._max_torques = twin.max_torques()  # the model's force range: fixed

    def _connect(self) -> None:
        self._torque = self.twin.torque_enabled()

    def _disconnect(self) -> None:
        pass

    def _read(self) -> JointState:
        q, qd, tau, now = self.twin.joint_reading()
        return JointState(q, qd, tau / self._max_torques, _ROOM_C, _NO_ERRORS, now)

    def _send(self, positions: np.ndarray) -> None:
        self.twin.set_targets(positions)

    def _set_torque(self, enabled: bool) -> None:
        self.twin.set_torque(enabled)

    def _initial_command(self) -> np.ndarray:
        # The twin's actuator targets are part of its saved state: after a restore, the next
        # command is bounded from them exactly as in the uninterrupted run.
        return self.twin.targets()
