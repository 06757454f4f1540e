"""How the arm contract suite builds each backend's ``Arm`` and reads, through that arm's own
link, whether its servos hold torque. Run as a script, it is the child process of the signal
test (``test_arm_contract.py::test_torque_goes_off_on_sigint_and_sigterm``)::

    python tests/robot/contract/arms.py KIND ADDRESS WHERE
    # KIND: twin, dynamixel, canopen; WHERE: emulated or real

The child connects, turns torque on and holds the pose it found (reads only, never a move)
inside ``robot.signals.torque_off_on_signals``, prints ``on``; on SIGINT or SIGTERM it prints
``stopped EXCEPTION BITS`` (BITS: one 0/1 per joint, the torque read back from the servos
through its link) and waits for ``again`` on stdin (torque on again, the next signal) or
anything else (leave). The twin's child runs its own twin, stepped one control period a tick.

This file is loaded by ``conftest.py`` by path (the tests are not a package), so that the
arms of the child and of the parent are built in one place.
"""

from __future__ import annotations

import os
import sys
import time

import numpy as np

from robot.arm import Arm, RecoveryPolicy
from robot.spec import CONTROL_RATE_HZ, ArmSpec, ergo_jr_spec

PERIOD_S = 1.0 / CONTROL_RATE_HZ  # one control tick, s (40 Hz: robot/spec.py)
# The largest step per command the suite lets any backend take, rad: 0.02 rad a tick at 40 Hz
# is 0.8 rad/s, about 7% of the XL-320's no-load speed (11.9 rad/s, ROBOTIS datasheet) and
# 1/7 of the project's own bound (robot.spec.ERGO_JR_MAX_STEP). A choice: slow on purpose, so
# that the suite is gentle on a real arm.
CONTRACT_MAX_STEP = 0.02
# Reply slack per Dynamixel exchange over an emulator's pty, s: as tests/system/test_link_loss.py
# (the emulator thread shares two busy cores; 20 ms let a ping fail its 3 tries once).
EMULATED_DYNAMIXEL_LATENCY_S = 0.05
# The TPDO wait of the suite's CAN arm, s: the settings of tests/system/test_can_faults.py's
# pty case (50 ms for the TPDOs ride out a loaded machine). Its heartbeat and SDO timeout on
# the emulator's pty are the product's own for a pty (``robot.canopen.arm.PTY_SETTINGS``,
# through ``config_for``); a real bus keeps the defaults.
CAN_PDO_TIMEOUT_S = 0.05

# Half-width of the joint window the suite commands in, around the pose found at connect, rad
# (5.7 degrees): every goal of the suite stays inside it and inside the Ergo Jr's limits. A
# choice: small enough for a real arm standing in free space, large enough to be read back
# (an XL-320 reads in 0.005 rad steps; the drives of the CAN emulator in 1e-4 rad).
WINDOW_RAD = 0.1
# Largest difference between a position read back and the goal the arm holds, rad, once it
# has had HOLD_S to get there. Measured on 2026-12-02 (this suite, load 3-4 on 2 cores): at
# most 0.012 rad on the twin and both emulators, and 0.026 rad on the Dynamixel emulator's
# twin at a slumped pose (m2 at -0.73 rad, the arm's weight on the shoulder). 0.05 rad
# (2.9 degrees) leaves room for a real XL-320's compliance under the Ergo Jr's weight (guess).
HOLD_TOLERANCE_RAD = 0.05
HOLD_S = 0.5  # time given to reach and hold a goal 0.1 rad away at 0.8 rad/s, s (guess)
BOUND_S = 30.0  # a bound against hangs (connect, child start), not an expectation
# How long an emulator may take to apply a torque off that reached it, s: a bound for its
# threads waiting for a CPU at load 8-18 on 2 cores, not a figure of the host (whose torque-off
# latency is tests/system/test_signals_bus.py's); a guess, 20 x the 100 ms bound.
LIMP_S = 2.0


def contract_spec() -> ArmSpec:
    """The Ergo Jr's joints and limits with the suite's small step bound."""
    return ergo_jr_spec(max_step=CONTRACT_MAX_STEP)


def make_arm(
    kind: str,
    address: str,
    emulated: bool = True,
    spec: ArmSpec | None = None,
    recovery: RecoveryPolicy | None = None,
    twin: object | None = None,
) -> Arm:
    """A new, unconnected arm of backend ``kind``.

    Args:
        kind: ``twin`` (``SimArm`` on ``twin``), ``dynamixel`` (``DynamixelArm`` on the serial
            port ``address``; a pty gets the emulator's slack) or ``canopen`` (``CanArm`` on
            the CAN bus ``address``, e.g. ``slcan:/dev/pts/7``, ``socketcan:can0``).
        address: the port or bus (ignored for the twin).
        emulated: an emulator answers (the Dynamixel bus then gets the emulator's slack; the
            CAN arm gets the pty's settings from its address);
            a real Dynamixel arm's baud rate is ``ERGO_TEST_BAUD`` (default 1 Mbit/s, the
            Poppy Ergo Jr's).
        spec: joints, limits, step bound (default ``contract_spec()``).
        recovery: reconnection policy after a lost link (default the arm's).
        twin: the twin of a ``twin`` arm.
    """
    spec = spec or contract_spec()
    if kind == "twin":
        from sim.arm import SimArm

        if twin is None:
            raise ValueError("a twin arm needs its twin")
        return SimArm(twin, spec=spec)
    if kind == "dynamixel":
        from robot.dynamixel.arm import DynamixelArm
        from robot.dynamixel.bus import DEFAULT_BAUD, DEFAULT_LATENCY_S

        latency = EMULATED_DYNAMIXEL_LATENCY_S if emulated else DEFAULT_LATENCY_S
        baud = DEFAULT_BAUD if emulated else int(os.environ.get("ERGO_TEST_BAUD", DEFAULT_BAUD))
        return DynamixelArm(address, baud=baud, spec=spec, latency_s=latency, recovery=recovery)
    if kind == "canopen":
        from robot.canopen.arm import CanArm, config_for

        config = config_for(address, pdo_timeout_s=CAN_PDO_TIMEOUT_S)  # a pty: PTY_SETTINGS
        return CanArm(address, spec=spec, config=config, recovery=recovery)
    raise ValueError(f"unknown arm kind {kind!r}: expected twin, dynamixel or canopen")


def torque_bits(arm: Arm) -> np.ndarray:
    """Torque on per joint, shape (n,) bool, as the servos report it through the arm's own
    link (not what the arm believes): the Dynamixel Torque Enable registers, the CiA 402 state
    of each drive (OPERATION ENABLED after a fresh SYNC cycle), the twin's actuator gains. The
    arm must be connected, except the twin's."""
    from robot.canopen.arm import CanArm
    from robot.dynamixel.arm import DynamixelArm
    from sim.arm import SimArm

    if isinstance(arm, SimArm):
        from sim.twin import JOINTS

        model = arm.twin.model
        return np.array([model.actuator(j).gainprm[0] > 0 for j in JOINTS])
    if isinstance(arm, DynamixelArm):
        reg = arm.model.reg("torque")
        data = arm.bus.sync_read(reg.address, reg.size, arm.ids)
        return np.array([reg.decode(data[i]) == 1 for i in arm.ids])
    if isinstance(arm, CanArm):
        from robot.canopen.cia402 import State

        arm.read()  # a SYNC cycle: the statuswords are this cycle's
        return arm.net.states_are(State.OPERATION_ENABLED)
    raise TypeError(f"no torque read-back for {type(arm).__name__}")


def _child(kind: str, address: str, where: str) -> int:
    from robot.signals import torque_off_on_signals

    twin = None
    if kind == "twin":
        from sim.twin import Twin

        twin = Twin(render_size=(32, 32))
    arm = make_arm(kind, address, emulated=where == "emulated", twin=twin)
    with arm:
        while True:
            try:
                with torque_off_on_signals(arm):
                    arm.set_torque(True)  # holds the pose it finds: no move
                    print("on", flush=True)
                    while True:
                        arm.read()
                        if twin is not None:
                            twin.step(PERIOD_S)
                        time.sleep(PERIOD_S)
            except (KeyboardInterrupt, SystemExit) as exc:
                bits = "".join("1" if b else "0" for b in torque_bits(arm))
                print("stopped", type(exc).__name__, bits, flush=True)
            if sys.stdin.readline().strip() != "again":
                return 0


if __name__ == "__main__":
    sys.exit(_child(*sys.argv[1:4]))
