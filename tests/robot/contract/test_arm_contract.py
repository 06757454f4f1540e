"""The arm contract: what every ``robot.Arm`` must do, each behaviour written once and run on
every backend of ``conftest.py`` (the twin, the Dynamixel emulator over a pty, the CANopen
emulator over SLCAN, and a real arm when ``ERGO_TEST_PORT`` or ``ERGO_TEST_CAN`` is set).

Every goal stays within ``conftest.WINDOW_RAD`` of the pose the arm was found in, at most
``arms.CONTRACT_MAX_STEP`` per command, so a real arm only makes small, slow moves
(docs/arm_contract.md). A behaviour a backend cannot show here (pulling a real adapter out,
injecting faults into a real bus, losing the twin's in-process link) is skipped with the
reason. Waits are bounded against hangs; nothing asserts on durations (the torque-off latency
under load is tests/system/test_signals_bus.py's).
"""

from __future__ import annotations

import contextlib
import logging
import os
import select
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import ergo_contract_arms as arms
import numpy as np
import pytest

from robot.arm import ArmCounters, RecoveryPolicy
from robot.errors import NotConnectedError, RobotError, SafetyStop
from robot.spec import ergo_jr_spec

ROOT = Path(__file__).resolve().parents[3]  # the repository (tests/robot/contract/ is 3 deep)
ARMS_PY = Path(__file__).with_name("arms.py")
ERGO_JR = ergo_jr_spec()
# python-can's notifier thread dies with an SLCAN adapter pulled out (its serial read fails),
# as it does with a real one: expected, as in tests/system/test_can_faults.py.
DEAD_NOTIFIER = pytest.mark.filterwarnings("ignore::pytest.PytestUnhandledThreadExceptionWarning")


def test_connect_and_read_give_finite_joint_states_in_radians(backend) -> None:
    arm = backend.arm()
    with pytest.raises(NotConnectedError):
        arm.read()
    with arm:
        assert arm.is_connected
        first, second = arm.read(), arm.read()
    assert not arm.is_connected
    n = ERGO_JR.n
    for state in (first, second):
        for name in ("positions", "velocities", "loads", "temperatures", "errors"):
            assert getattr(state, name).shape == (n,), name
        assert np.all(np.isfinite(state.positions)) and np.all(np.isfinite(state.velocities))
        # radians: inside the Ergo Jr's limits (a little slack for an arm moved by hand),
        # which no reading in degrees or raw servo units of a pose away from zero would be
        assert np.all(state.positions > ERGO_JR.lower - 0.1), state.positions
        assert np.all(state.positions < ERGO_JR.upper + 0.1), state.positions
        assert np.isfinite(state.timestamp)
    assert second.timestamp >= first.timestamp
    moved = np.abs(second.positions - first.positions).max()
    assert moved < arms.HOLD_TOLERANCE_RAD, moved  # nothing was commanded


def test_a_command_beyond_the_limits_is_clamped_to_them(backend) -> None:
    with backend.arm() as arm:
        q0 = backend.narrow(arm)
        lower, upper = arm.spec.lower, arm.spec.upper
        assert np.all(lower >= ERGO_JR.lower) and np.all(upper <= ERGO_JR.upper)
        arm.set_torque(True)
        steps = int(np.ceil(2 * arms.WINDOW_RAD / arm.spec.max_step))  # edge to edge
        for goal, limit in ((q0 + 10.0, upper), (q0 - 10.0, lower)):
            for _ in range(steps + 4):  # far past the limit: the goal stops at it
                sent = arm.command(goal)
                assert np.all(sent >= lower) and np.all(sent <= upper), sent
                backend.tick()
            assert np.array_equal(sent, limit), (sent, limit)
            # the arm never goes past the limit (reaching a goal is the hold test's: here a
            # limp arm that slumped onto the table between tests may be stopped short by it)
            readings = backend.hold(arm)
            assert np.all(readings <= upper + arms.HOLD_TOLERANCE_RAD)
            assert np.all(readings >= lower - arms.HOLD_TOLERANCE_RAD)
        before = arm.last_sent
        with pytest.raises(ValueError, match="non-finite"):
            arm.command(np.full(6, np.nan))
        with pytest.raises(ValueError, match="shape"):
            arm.command(np.zeros(5))
        assert np.array_equal(arm.last_sent, before)  # refused commands send nothing


def test_a_big_jump_is_limited_to_the_max_step_per_command(backend) -> None:
    with backend.arm() as arm:
        q0 = backend.narrow(arm)
        arm.set_torque(True)
        start = arm.last_sent
        step = arm.spec.max_step
        centre = (arm.spec.lower + arm.spec.upper) / 2
        jump = np.where(start <= centre, 1.0, -1.0)  # 1 rad (50 steps) towards the room left
        sent = arm.command(q0 + jump)
        assert np.allclose(sent - start, step * np.sign(jump), atol=1e-12), sent - start
        sent_again = arm.command(q0 + jump)
        assert np.allclose(sent_again - sent, step * np.sign(jump), atol=1e-12)
        readings = backend.hold(arm)
        # the arm went to the goal actually sent, two steps from where it was, no further
        assert np.abs(readings - start).max() <= 2 * step + arms.HOLD_TOLERANCE_RAD
        assert np.abs(readings[-1] - sent_again).max() < arms.HOLD_TOLERANCE_RAD


def test_torque_on_holds_the_pose(backend) -> None:
    """Torque on holds the pose found (no jump to an old goal), then a goal reached stays."""
    with backend.arm() as arm:
        q0 = backend.narrow(arm)
        arm.set_torque(True)
        assert arm.torque_enabled and backend.torque(arm).all()
        found = backend.hold(arm, seconds=0.3)
        assert np.abs(found - q0).max() < arms.HOLD_TOLERANCE_RAD, np.abs(found - q0).max()
        centre = (arm.spec.lower + arm.spec.upper) / 2
        goal = centre + np.array([0.06, -0.06, 0.06, -0.06, 0.06, -0.06])  # inside the window
        for _ in range(10):
            arm.command(goal)
            backend.tick()
        readings = backend.hold(arm, seconds=1.0)
        settled = readings[len(readings) // 2 :]  # after 0.5 s: held, not drifting
        assert np.abs(settled - goal).max() < arms.HOLD_TOLERANCE_RAD, np.abs(settled - goal).max()
        assert backend.torque(arm).all()


def test_torque_goes_off_on_normal_exit(backend) -> None:
    with backend.arm() as arm:
        backend.narrow(arm)
        arm.set_torque(True)
        assert backend.torque(arm).all()
    assert not arm.is_connected and not arm.torque_enabled
    assert not backend.torque().any(), backend.torque()


def test_torque_goes_off_on_an_exception_inside_the_with(backend) -> None:
    class Boom(Exception):
        pass

    with pytest.raises(Boom, match="in the control loop"), backend.arm() as arm:
        q0 = backend.narrow(arm)
        arm.set_torque(True)
        arm.command(q0)
        raise Boom("in the control loop")
    assert not arm.is_connected
    assert not backend.torque().any(), backend.torque()


def _line(proc: subprocess.Popen) -> str:
    ready, _, _ = select.select([proc.stdout], [], [], arms.BOUND_S)
    assert ready, "the child said nothing"
    line = proc.stdout.readline()
    assert line, f"the child ended: {proc.wait(timeout=5)} {proc.stderr.read()[-2000:]}"
    return line.strip()


def test_torque_goes_off_on_sigint_and_sigterm(backend) -> None:
    """A child process holds the arm inside ``torque_off_on_signals``; after each signal it
    reads the torque back from the servos through its own link, and, on an emulator, the
    servos themselves are looked at from here before the child goes on."""
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
    proc = subprocess.Popen(
        [sys.executable, str(ARMS_PY), *backend.child_args()], cwd=ROOT, env=env, text=True,
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
        start_new_session=True,
    )  # fmt: skip
    try:
        for sig, expected in ((signal.SIGINT, "KeyboardInterrupt"), (signal.SIGTERM, "SystemExit")):
            assert _line(proc) == "on"
            if backend.sees_torque_while_held:
                assert backend.torque().all()
            time.sleep(0.1)
            os.kill(proc.pid, sig)
            assert _line(proc) == f"stopped {expected} 000000"
            if backend.sees_torque_while_held:
                assert not backend.torque().any(), backend.torque()
            proc.stdin.write("again\n" if sig == signal.SIGINT else "quit\n")
            proc.stdin.flush()
        assert proc.wait(timeout=arms.BOUND_S) == 0, proc.stderr.read()[-2000:]
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    assert not backend.torque().any()


@DEAD_NOTIFIER
def test_a_link_lost_and_back_is_recovered_holding_the_pose(backend) -> None:
    if backend.no_unplug:
        pytest.skip(backend.no_unplug)
    with backend.arm() as arm:
        q0 = backend.narrow(arm)
        arm.set_torque(True)
        arm.command(q0)
        held = backend.hold(arm, seconds=0.2)[-1]  # where it holds (under its own weight)
        backend.unplug()
        timer = threading.Timer(0.3, backend.replug)
        timer.start()
        try:
            readings = backend.hold(arm, seconds=1.0)  # the first read recovers
        finally:
            timer.join()
        counts = arm.fault_counts()
        assert counts["links_lost"] >= 1 and counts["reconnects"] == counts["links_lost"], counts
        assert counts["stops_after_link_loss"] == 0 and counts["recovery_s"] > 0, counts
        assert arm.torque_enabled and backend.torque(arm).all()  # back on, holding
        # held where it was (the recovery holds the pose measured after the loss: under load
        # that may be one steady-state error further down than the goal held before)
        assert np.all(np.isfinite(readings))
        assert np.abs(readings - held).max() < arms.HOLD_TOLERANCE_RAD, readings - held
        here = arm.read().positions
        sent = arm.command(q0 + 1.0)  # the step bound restarted from the measured pose
        assert np.abs(sent - here).max() <= arm.spec.max_step + arms.HOLD_TOLERANCE_RAD
    assert not backend.torque().any()


@DEAD_NOTIFIER
def test_a_link_lost_for_good_ends_in_a_safety_stop(backend) -> None:
    if backend.no_unplug:
        pytest.skip(backend.no_unplug)
    fast = RecoveryPolicy(attempts=3, first_delay_s=0.05, max_delay_s=0.1)
    with backend.arm(recovery=fast) as arm:
        q0 = backend.narrow(arm)
        arm.set_torque(True)
        arm.command(q0)
        backend.unplug()  # and it stays out
        deadline = time.monotonic() + arms.BOUND_S
        with pytest.raises(SafetyStop) as info:
            while time.monotonic() < deadline:  # a stop, never a hang nor a silent success
                arm.command(q0)
                backend.tick()
                arm.read()
        message = str(info.value)
        assert "\n" not in message and "safety stop" in message, message
        assert not arm.torque_enabled
    backend.replug()  # the adapter is back: a new arm takes over and turns torque off
    with backend.arm() as again:
        again.read()
    assert not backend.torque().any()


def test_fault_counters_exist_and_count_the_traffic(backend) -> None:
    with backend.arm() as arm:
        backend.narrow(arm)
        before = arm.fault_counts()
        for _ in range(10):
            arm.read()
        after = arm.fault_counts()
    for key in ArmCounters.__dataclass_fields__:
        assert key in after, key
    assert all(isinstance(v, int | float) and np.isfinite(v) and v >= 0 for v in after.values())
    assert after["links_lost"] == 0 and after["stops_after_link_loss"] == 0
    if backend.traffic_counter is not None:
        assert after[backend.traffic_counter] >= before[backend.traffic_counter] + 10, after
    else:  # the twin: nothing but the arm's own link counters, none of which moved
        assert set(after) == set(ArmCounters.__dataclass_fields__), after
        assert after == before


def test_injected_bus_faults_are_counted_and_absorbed(backend) -> None:
    if backend.no_faults:
        pytest.skip(backend.no_faults)
    keys = {"bus_calls": ("bus_timeouts", "bus_retries"), "can_cycles": ("can_missing_tpdos",)}
    wanted = keys[backend.traffic_counter]
    with backend.arm() as arm:
        q0 = backend.narrow(arm)
        arm.set_torque(True)
        with backend.faults():
            for _ in range(500):  # until a fault is counted (expected within about 10)
                arm.command(q0)
                state = arm.read()
                counts = arm.fault_counts()
                if all(counts[k] > 0 for k in wanted):
                    break
        assert all(counts[k] > 0 for k in wanted), counts
        assert np.abs(state.positions - q0).max() < arms.HOLD_TOLERANCE_RAD
    assert not backend.torque().any()


# Wire faults injected by a pty proxy between the arm and the emulator (tests/wire_proxy.py),
# toward the host: what each does to the proxy. Rates are fractions of the wire's units (SLCAN
# lines, Dynamixel packets); the garbage is random bytes at 11.5 kB/s between units and a few
# before each unit (no unit comes through untouched).
WIRE_FAULTS = {
    "garbage-50ms": lambda proxy: proxy.garbage(0.05),
    "garbage-1.5s": lambda proxy: proxy.garbage(1.5),
    "drops": lambda proxy: setattr(proxy.to_host.faults, "drop_rate", 0.02),
    "truncated": lambda proxy: setattr(proxy.to_host.faults, "truncate_rate", 0.02),
    "delayed": lambda proxy: (
        setattr(proxy.to_host.faults, "delay_rate", 0.05),
        setattr(proxy.to_host.faults, "delay_s", 0.03),
    ),
}
WIRE_FAULT_S = 1.5  # how long the arm holds its pose under the fault, s


def _limp_within(backend, seconds: float) -> bool:
    """Whether the servos read back limp (from the emulator itself) within ``seconds``: the
    emulator applies what reached it in its own threads, which wait for a CPU on a loaded
    machine (a real servo applies it within microseconds)."""
    deadline = time.monotonic() + seconds
    while backend.torque().any():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.01)
    return True


@pytest.mark.filterwarnings("error::pytest.PytestUnhandledThreadExceptionWarning")
@pytest.mark.parametrize("fault", list(WIRE_FAULTS))
def test_wire_faults_end_with_the_arm_limp_and_at_most_one_line(backend, fault, caplog) -> None:
    """The arm holds its pose (torque on) through a proxy that garbles, drops, truncates or
    delays what the servos send; it either rides the fault out or stops with one line (a
    ``RobotError``, never another exception, never a thread's traceback). Stopped by a
    ``SafetyStop``, the servos are limp at once, as the emulator itself says (not the arm
    under test), while the fault goes on; in every case they are limp once the arm is left,
    the fault still on.

    What each bus must do besides: a 50 ms burst of garbage is ridden out on both (the
    Dynamixel decoder skips garbage between packets; the CANopen host drops garbled SLCAN
    lines and excuses a heartbeat the line ate while the drive's TPDOs kept coming); 1.5 s of
    it stops the CANopen arm (no frame comes through: "answered no SYNC"), never a traceback
    from python-can's reader thread (before: the thread died and the drives stayed enabled)."""
    if backend.no_faults:
        pytest.skip(backend.no_faults)
    with backend.wire_proxy(seed=hash(fault) % 1000) as proxy:
        arm = backend.arm_through(proxy)
        stop = None
        with arm:
            q0 = backend.narrow(arm)
            arm.set_torque(True)
            WIRE_FAULTS[fault](proxy)
            try:
                for _ in range(round(WIRE_FAULT_S / arms.PERIOD_S)):
                    arm.command(q0)
                    backend.tick()
                    arm.read()
            except RobotError as exc:
                stop = exc
                assert "\n" not in str(exc), str(exc)
                if isinstance(exc, SafetyStop):  # limp as soon as the emulator has applied it
                    assert _limp_within(backend, arms.LIMP_S), str(exc)
        counts = arm.fault_counts()
        faults = {k: v for k, v in proxy.to_host.counts.__dict__.items() if v}
    assert not backend.torque().any(), (stop, faults, counts)
    print(f"{backend.name} {fault}: {faults}; {stop or 'rode it out'}; {counts}")
    # an unconfirmed torque off is said once, not again by the disconnect after the stop
    unconfirmed = [r for r in caplog.records if "torque off not confirmed" in r.getMessage()]
    assert len([r for r in unconfirmed if r.levelno >= logging.WARNING]) <= 1, caplog.text
    if fault == "garbage-50ms":
        assert stop is None, stop
    if backend.kind == "canopen" and fault.startswith("garbage"):
        assert counts["can_garbled_lines"] > 0, counts
    if backend.kind == "canopen" and fault == "garbage-1.5s":
        assert isinstance(stop, SafetyStop), (stop, counts)
