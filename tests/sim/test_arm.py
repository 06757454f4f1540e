"""``SimArm``: the twin's arm goes through the base class's clamp and follows its commands."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from robot.spec import ergo_jr_spec
from sim.arm import SimArm
from sim.twin import Twin

SPEC = ergo_jr_spec()
wild = arrays(np.float64, (6,), elements=st.floats(-20, 20))


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
