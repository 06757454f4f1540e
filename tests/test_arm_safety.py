"""Safety of every command: limits and maximum step, torque off on exit, exception and signals,
the thermal/load watchdog."""

from __future__ import annotations

import os
import signal

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from robot.arm import JointState
from robot.errors import NotConnectedError, SafetyStop
from robot.signals import torque_off_on_signals
from robot.spec import ergo_jr_spec
from robot.watchdog import Watchdog
from sim.arm import SimArm
from sim.twin import Twin

SPEC = ergo_jr_spec()
wild = arrays(np.float64, (6,), elements=st.floats(-20, 20))


@settings(max_examples=300, deadline=None)
@given(wild, wild)
def test_clamp_never_leaves_limits_or_exceeds_max_step(target, previous):
    prev = np.clip(previous, SPEC.lower, SPEC.upper)
    out = SPEC.clamp(target, prev)
    assert np.all(out >= SPEC.lower) and np.all(out <= SPEC.upper)
    assert np.all(np.abs(out - prev) <= SPEC.max_step + 1e-12)


def test_clamp_refuses_nan_and_wrong_shape():
    with pytest.raises(ValueError, match="non-finite"):
        SPEC.clamp(np.array([0, 0, np.nan, 0, 0, 0]), None)
    with pytest.raises(ValueError, match="shape"):
        SPEC.clamp(np.zeros(5), None)


@pytest.fixture(scope="module")
def shared_twin():
    t = Twin(render_size=(64, 64))
    yield t
    t.close()


@settings(max_examples=30, deadline=None)
@given(st.lists(wild, min_size=1, max_size=15))
def test_sim_arm_commands_never_exceed_limits_or_max_step(shared_twin, commands):
    shared_twin.reset()
    with SimArm(shared_twin) as arm:
        prev = arm.last_sent
        for c in commands:
            sent = arm.command(c)
            assert np.all(sent >= SPEC.lower) and np.all(sent <= SPEC.upper)
            assert np.all(np.abs(sent - prev) <= SPEC.max_step + 1e-12)
            np.testing.assert_array_equal(shared_twin.targets(), sent)
            prev = sent
            shared_twin.step(0.025)


def test_read_tracks_commands(twin):
    goal = np.array([0.4, 0.6, -0.3, 0.2, 0.3, -0.2])
    with SimArm(twin) as arm:
        for _ in range(80):  # 2 s at 40 Hz
            arm.command(goal)
            twin.step(0.025)
        np.testing.assert_allclose(arm.read().positions, goal, atol=0.05)


def test_torque_goes_off_on_exit_and_on_exception(twin):
    with SimArm(twin) as arm:
        arm.set_torque(True)
        assert twin.torque_enabled()
    assert not twin.torque_enabled() and not arm.is_connected

    with pytest.raises(RuntimeError, match="boom"), SimArm(twin) as arm:
        arm.set_torque(True)
        raise RuntimeError("boom")
    assert not twin.torque_enabled()


def test_commands_need_a_connection(twin):
    with pytest.raises(NotConnectedError, match="connect"):
        SimArm(twin).command(np.zeros(6))


@pytest.mark.parametrize(
    "sig, exc", [(signal.SIGINT, KeyboardInterrupt), (signal.SIGTERM, SystemExit)]
)
def test_signals_turn_torque_off_then_raise(twin, sig, exc):
    with SimArm(twin) as arm:
        arm.set_torque(True)
        with pytest.raises(exc), torque_off_on_signals(arm):
            os.kill(os.getpid(), sig)
            for _ in range(1000):  # the handler runs between bytecodes
                pass
        assert not twin.torque_enabled()


@pytest.mark.parametrize(
    "sig, exc", [(signal.SIGINT, KeyboardInterrupt), (signal.SIGTERM, SystemExit)]
)
def test_a_signal_turned_into_another_error_inside_the_block_still_ends_it(twin, sig, exc):
    # as zipfile does inside numpy.savez: its cleanup raised ValueError over the interrupt,
    # and `ergo explore` exited with 1 instead of 130 (1 of 40 SIGINTs at random moments)
    with SimArm(twin) as arm:
        arm.set_torque(True)
        with pytest.raises(exc) as info, torque_off_on_signals(arm):
            try:
                os.kill(os.getpid(), sig)
                for _ in range(1000):  # the handler runs between bytecodes
                    pass
            finally:
                raise ValueError("Can't close the ZIP file")
        assert isinstance(info.value.__cause__, ValueError)
        if exc is SystemExit:
            assert info.value.code == 128 + signal.SIGTERM
        assert not twin.torque_enabled()
        with pytest.raises(ValueError), torque_off_on_signals(arm):  # no signal: errors pass
            raise ValueError("not an interrupt")


def test_enabling_torque_holds_the_current_pose(twin):
    """A limp arm moved by hand must not jump back to its old command when torque returns."""
    with SimArm(twin) as arm:
        arm.set_torque(False)
        twin.data.qpos[twin._qpos_idx[1]] = 0.7  # moved by hand
        twin.step()
        arm.set_torque(True)
        assert arm.last_sent[1] == pytest.approx(twin.joint_positions()[1], abs=1e-6)


def _state(t, load=0.0, temp=30.0):
    return JointState.from_positions(
        np.zeros(6), t, loads=np.full(6, load), temperatures=np.full(6, temp)
    )


def test_watchdog_trips_on_sustained_overload_only():
    w = Watchdog(max_load=0.9, hold_s=1.0, max_gap_s=0.1)
    assert all(w.check(_state(t * 0.05, load=0.95)) is None for t in range(20))  # 0.95 s
    reason = w.check(_state(1.0, load=0.95))
    assert reason is not None and "load" in reason and "torque off" in reason


def test_watchdog_ignores_short_peaks_gaps_and_unknown_values():
    w = Watchdog(max_load=0.9, hold_s=1.0, max_gap_s=0.1)
    for t in range(40):
        load = 0.95 if t % 10 else 0.1  # dips below the limit every 0.5 s
        assert w.check(_state(t * 0.05, load=load)) is None
    w2 = Watchdog(max_load=0.9, hold_s=1.0, max_gap_s=0.1)
    assert all(w2.check(_state(t * 0.5, load=0.95)) is None for t in range(10))  # sparse reads
    w3 = Watchdog()
    assert all(w3.check(_state(t * 0.05, load=np.nan, temp=np.nan)) is None for t in range(100))


def test_watchdog_stop_turns_torque_off(twin):
    with SimArm(twin, watchdog=Watchdog(max_temperature_c=20.0, hold_s=0.0)) as arm:
        arm.set_torque(True)
        with pytest.raises(SafetyStop, match="temperature"):
            arm.read()  # the twin reports 25 C
        assert not twin.torque_enabled()
