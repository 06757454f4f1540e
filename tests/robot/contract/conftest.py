"""The backends of the arm contract suite: every test of ``test_arm_contract.py`` takes the
``backend`` fixture and runs once on each of

- ``twin``: ``SimArm`` on the MuJoCo twin, in-process (physics stepped one control tick at a
  time by ``Backend.tick``);
- ``dynamixel-pty``: ``DynamixelArm`` on six emulated XL-320 (``DynamixelEmulator`` on a twin
  in real time) served on a pseudo-terminal behind a stable link (``PtyBusServer``);
- ``canopen-slcan``: ``CanArm`` on six emulated CiA 402 drives (``EmulatedDrives``, the twin
  stepped one control period per SYNC) behind an SLCAN adapter on a pseudo-terminal
  (``SlcanPtyBridge``), opened as ``slcan:LINK``;
- ``dynamixel-real``: a real arm on ``ERGO_TEST_PORT`` (e.g. ``/dev/ttyUSB0``; baud rate
  ``ERGO_TEST_BAUD``, default 1000000), skipped, saying so, when it is not set;
- ``canopen-real``: a real arm on ``ERGO_TEST_CAN`` (e.g. ``socketcan:can0``), skipped,
  saying so, when it is not set.

A backend lives for the module (one twin and emulator per backend, not per test); each test
gets it plugged in, without injected faults, with no arm connected. docs/arm_contract.md says
how to run the suite on a real rig and what it moves.
"""

from __future__ import annotations

import contextlib
import importlib.util
import os
import sys
import time
import uuid
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np
import pytest

from robot.arm import Arm, RecoveryPolicy


def _load(name: str, path: Path) -> ModuleType:
    """A helper module by path (the tests are not a package), registered as ``name``."""
    spec = importlib.util.spec_from_file_location(name, path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # the test module imports it by this name
    spec.loader.exec_module(module)
    return module


arms = _load("ergo_contract_arms", Path(__file__).with_name("arms.py"))
# the pty proxy that injects wire faults (tests/wire_proxy.py)
wire_proxy = _load("ergo_wire_proxy", Path(__file__).resolve().parents[2] / "wire_proxy.py")

REAL_PORT_VAR = "ERGO_TEST_PORT"
REAL_CAN_VAR = "ERGO_TEST_CAN"


class Backend:
    """One backend of the suite: how to build its arm, what the servos say from outside the
    arm under test, how to let time pass, and what can be done to its link.

    Attributes:
        name: the test id.
        kind, address, emulated: what ``arms.make_arm`` builds.
        traffic_counter: the ``fault_counts`` key that counts the bus traffic (None: the twin
            has no bus).
        no_unplug: why the link cannot be pulled out by the suite (None: it can).
        no_faults: why faults cannot be injected (None: they can).
        twin: the twin behind the arm, if any.
    """

    name = ""
    kind = ""
    address = ""
    emulated = True
    traffic_counter: str | None = None
    no_unplug: str | None = None
    no_faults: str | None = None
    twin = None
    #: how the wire is cut into units for the fault proxy (``wire_proxy.FRAMERS``); None: no
    #: wire to put a proxy on (``no_faults`` says why)
    framing: str | None = None
    #: the emulator's port, which the fault proxy opens as its device
    device = ""

    def arm(self, recovery: RecoveryPolicy | None = None) -> Arm:
        """A new, unconnected arm with the suite's step bound (``arms.contract_spec``)."""
        return arms.make_arm(
            self.kind, self.address, emulated=self.emulated, recovery=recovery, twin=self.twin
        )

    def child_args(self) -> list[str]:
        """The argv of ``arms.py`` run as the signal test's child on this backend."""
        return [self.kind, self.address or "-", "emulated" if self.emulated else "real"]

    @property
    def sees_torque_while_held(self) -> bool:
        """Whether ``torque`` works while another process holds the link (an emulator)."""
        return self.emulated

    def tick(self) -> None:
        """Let one control period pass (the twin's physics is stepped by the suite)."""
        time.sleep(arms.PERIOD_S)

    def unplug(self) -> None:
        raise NotImplementedError

    def replug(self) -> None:
        raise NotImplementedError

    @contextlib.contextmanager
    def faults(self) -> Iterator[None]:
        """Inject bus faults inside the block (lost replies or frames)."""
        raise NotImplementedError
        yield

    @contextlib.contextmanager
    def wire_proxy(self, seed: int = 0) -> Iterator[Any]:
        """A ``wire_proxy.WireProxy`` between the emulator's port and the arms of
        ``arm_through``, without faults until the test sets them."""
        assert self.framing is not None, self.no_faults
        with wire_proxy.WireProxy(self.device, self.framing, seed=seed) as proxy:
            yield proxy

    def arm_through(self, proxy: Any, recovery: RecoveryPolicy | None = None) -> Arm:
        """A new, unconnected arm that talks to the emulator through ``proxy``."""
        address = proxy.port if self.kind == "dynamixel" else f"slcan:{proxy.port}"
        return arms.make_arm(self.kind, address, emulated=True, recovery=recovery)

    def reset(self) -> None:
        """Before and after each test: plugged in, no injected faults."""

    def _limp(self) -> None:
        """Torque off if a test failed leaving it on (so that the next test starts limp, as
        after every passing test): an arm of the suite connects and leaves."""
        if self.torque().any():
            with self.arm():
                pass

    def close(self) -> None:
        """After the module."""

    # ---- helpers every test uses -----------------------------------------------------------
    def narrow(self, arm: Arm) -> np.ndarray:
        """Narrow the connected ``arm``'s limits to a window ``2 WINDOW_RAD`` wide holding the
        pose it reads now, centred on it unless a joint limit is nearer than ``WINDOW_RAD``
        (a limp arm may lie against a stop: the window then starts at the limit); never wider
        than the Ergo Jr's. Returns that pose, shape (6,), rad. A pose further than
        ``WINDOW_RAD`` outside the limits is a rig to set up, not a pass: the test fails."""
        q0 = arm.read().positions
        spec, w = arm.spec, arms.WINDOW_RAD
        joints = zip(spec.names, q0, spec.lower, spec.upper, strict=True)
        outside = [f"{n} {q:.3f}" for n, q, lo, hi in joints if not lo - w < q < hi + w]
        if outside:
            pytest.fail(
                f"{self.name}: the arm is outside its joint limits ({', '.join(outside)} rad): "
                f"put it in its rest pose first"
            )
        centre = np.clip(q0, spec.lower + w, spec.upper - w)
        arm.spec = spec.with_limits(centre - w, centre + w)
        arm.resync()
        return q0

    def torque(self, arm: Arm | None = None) -> np.ndarray:
        """Torque on per joint, shape (6,) bool, seen from outside the arm under test where
        the backend can (an emulator, the twin), else through ``arm``'s link."""
        raise NotImplementedError

    def hold(self, arm: Arm, seconds: float = arms.HOLD_S) -> np.ndarray:
        """Read the arm every tick for ``seconds``; returns the readings, shape (k, 6), rad."""
        readings = []
        for _ in range(max(1, round(seconds / arms.PERIOD_S))):
            self.tick()
            readings.append(arm.read().positions)
        return np.array(readings)


class TwinBackend(Backend):
    name, kind = "twin", "twin"
    no_unplug = "the twin's arm is in-process: it has no link to lose"
    no_faults = "the twin's arm has no bus to inject faults into"

    def __init__(self) -> None:
        from sim.twin import Twin

        self.twin = Twin(render_size=(32, 32))

    def torque(self, arm: Arm | None = None) -> np.ndarray:
        from sim.arm import SimArm

        return arms.torque_bits(SimArm(self.twin))  # reads the twin's actuators only

    @property
    def sees_torque_while_held(self) -> bool:
        return False  # the child runs its own twin

    def tick(self) -> None:
        self.twin.step(arms.PERIOD_S)

    def reset(self) -> None:
        self._limp()

    def close(self) -> None:
        self.twin.close()


class DynamixelPtyBackend(Backend):
    name, kind = "dynamixel-pty", "dynamixel"
    traffic_counter = "bus_calls"

    def __init__(self, tmp: Path) -> None:
        from sim.dynamixel.emulator import DynamixelEmulator
        from sim.dynamixel.server import PtyBusServer
        from sim.realtime import RealtimeLoop
        from sim.twin import Twin

        self.twin_served = Twin(render_size=(32, 32))
        self.emulator = DynamixelEmulator(self.twin_served)
        self.loop = RealtimeLoop(self.twin_served)
        self.server = PtyBusServer(self.emulator, link=tmp / "ttyERGO")
        self.loop.start()
        self.server.start()
        self.address = self.device = self.server.port
        self.framing = "dynamixel"

    def torque(self, arm: Arm | None = None) -> np.ndarray:
        return np.array(list(self.emulator.torque_states().values()))

    def unplug(self) -> None:
        self.server.unplug()

    def replug(self) -> None:
        self.server.replug()

    @contextlib.contextmanager
    def faults(self) -> Iterator[None]:
        # 2% of status packets lost: a retry about every 8 reads of six servos; a call fails
        # only when one servo loses 3 in a row (8e-6 a call and servo)
        self.emulator.faults.drop_rate = 0.02
        try:
            yield
        finally:
            self.emulator.faults.drop_rate = 0.0

    def reset(self) -> None:
        self.emulator.faults.drop_rate = 0.0
        self.server.replug()
        self._limp()

    def close(self) -> None:
        self.server.close()
        self.loop.stop()
        self.twin_served.close()


class CanSlcanBackend(Backend):
    name, kind = "canopen-slcan", "canopen"
    traffic_counter = "can_cycles"

    def __init__(self, tmp: Path) -> None:
        import can

        from sim.canopen.drives import EmulatedDrives
        from sim.canopen.server import SlcanPtyBridge
        from sim.twin import Twin

        channel = f"contract-{uuid.uuid4().hex[:8]}"
        self.twin_served = Twin(render_size=(32, 32))
        # the twin steps one control period per SYNC: no real-time loop competing for the CPU
        self.drives = EmulatedDrives(
            self.twin_served, f"virtual:{channel}", sync_step_s=arms.PERIOD_S
        )
        self.drives.start()
        self.bridge_bus = can.Bus(interface="virtual", channel=channel)
        self.bridge = SlcanPtyBridge(self.bridge_bus, link=tmp / "ttyCAN")
        self.bridge.start()
        self.device = self.bridge.port
        self.address = f"slcan:{self.device}"
        self.framing = "slcan"

    def torque(self, arm: Arm | None = None) -> np.ndarray:
        from robot.canopen.cia402 import State

        return np.array([s is State.OPERATION_ENABLED for s in self.drives.states().values()])

    def unplug(self) -> None:
        self.bridge.unplug()

    def replug(self) -> None:
        self.bridge.replug()

    @contextlib.contextmanager
    def faults(self) -> Iterator[None]:
        self.drives.drop_rate = 0.05  # PDO and SYNC frames lost, each way
        try:
            yield
        finally:
            self.drives.drop_rate = 0.0

    def reset(self) -> None:
        self.drives.drop_rate = 0.0
        self.bridge.replug()
        self._limp()

    def close(self) -> None:
        self.bridge.close()
        self.drives.stop()
        self.bridge_bus.shutdown()
        self.twin_served.close()


class RealBackend(Backend):
    emulated = False
    no_unplug = (
        "pulling a real adapter out needs a person at the rig: not automated (the emulators "
        "show it: dynamixel-pty, canopen-slcan)"
    )
    no_faults = "faults are not injected into a real bus"

    def __init__(self, name: str, kind: str, address: str) -> None:
        self.name, self.kind, self.address = name, kind, address
        self.traffic_counter = "bus_calls" if kind == "dynamixel" else "can_cycles"

    def torque(self, arm: Arm | None = None) -> np.ndarray:
        """Through ``arm``'s link while it is connected; else a fresh arm's read-back
        (connect, read, close leaving torque as it is: the port is free)."""
        if arm is not None and arm.is_connected:
            return arms.torque_bits(arm)
        arm = self.arm()
        arm.connect()
        try:
            return arms.torque_bits(arm)
        finally:
            arm.disconnect(torque_off=False)


BACKENDS = ["twin", "dynamixel-pty", "canopen-slcan", "dynamixel-real", "canopen-real"]


def _make(name: str, tmp: Path) -> Backend:
    if name == "twin":
        return TwinBackend()
    if name == "dynamixel-pty":
        return DynamixelPtyBackend(tmp)
    if name == "canopen-slcan":
        return CanSlcanBackend(tmp)
    var, kind = (
        (REAL_PORT_VAR, "dynamixel") if name == "dynamixel-real" else (REAL_CAN_VAR, "canopen")
    )
    address = os.environ.get(var, "")
    if not address:
        example = "/dev/ttyUSB0" if kind == "dynamixel" else "socketcan:can0"
        pytest.skip(f"no real arm: set {var}={example} to run the contract on a real {kind} arm")
    return RealBackend(name, kind, address)


@pytest.fixture(scope="module", params=BACKENDS)
def _served(
    request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory
) -> Iterator[Backend]:
    backend = _make(request.param, tmp_path_factory.mktemp(request.param))
    try:
        yield backend
    finally:
        backend.close()


@pytest.fixture
def backend(_served: Backend) -> Iterator[Backend]:
    """The backend under test, plugged in, without injected faults."""
    _served.reset()
    yield _served
    _served.reset()
