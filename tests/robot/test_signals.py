"""SIGINT and SIGTERM inside ``torque_off_on_signals``: torque off at once, then the usual
exception (tests/system/test_signals*.py: the same for processes and over the buses)."""

from __future__ import annotations

import os
import signal

import numpy as np
import pytest
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from robot.signals import torque_off_on_signals
from robot.spec import ergo_jr_spec
from sim.arm import SimArm

SPEC = ergo_jr_spec()
wild = arrays(np.float64, (6,), elements=st.floats(-20, 20))


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
