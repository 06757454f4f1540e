"""The thermal/load watchdog: it trips on a sustained overload or overheat only, and the arm then
cuts torque."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from robot.arm import JointState
from robot.errors import SafetyStop
from robot.spec import ergo_jr_spec
from robot.watchdog import Watchdog
from sim.arm import SimArm

SPEC = ergo_jr_spec()
wild = arrays(np.float64, (6,), elements=st.floats(-20, 20))


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
