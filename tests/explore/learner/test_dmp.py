"""Motor primitives: shapes, limits for any parameters, convergence, clear refusals."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from explore.learner.dmp import N_PARAMS, ParameterError
from explore.rigs.motor import ergo_jr_dmp

params = arrays(np.float64, (N_PARAMS,), elements=st.floats(-1.0, 1.0))
DMP = ergo_jr_dmp()


def test_shape_is_48_to_40_by_6():
    traj = DMP.trajectory(np.zeros(N_PARAMS))
    assert traj.shape == (40, 6)


@settings(max_examples=200, deadline=None)
@given(params)
def test_trajectory_stays_inside_the_joint_ranges_for_any_parameters(theta):
    traj = DMP.trajectory(theta)
    assert np.all(traj >= DMP.lower - 1e-12) and np.all(traj <= DMP.upper + 1e-12)


@settings(max_examples=50, deadline=None)
@given(params)
def test_closed_form_equals_step_by_step_integration(theta):
    np.testing.assert_allclose(DMP.normalised(theta), DMP.normalised_reference(theta), atol=1e-9)


def test_converges_to_the_goal():
    theta = np.zeros(N_PARAMS).reshape(6, 8)
    goals = np.array([0.5, -0.3, 0.8, -0.9, 0.1, 0.0])
    theta[:, 7] = goals
    long = ergo_jr_dmp(n_points=200)  # 5 s: the transient has died out
    y = long.normalised(theta.ravel())
    np.testing.assert_allclose(y[-1], goals, atol=1e-3)
    # and the 1 s trajectory is already most of the way there
    y1 = DMP.normalised(theta.ravel())
    assert np.all(np.abs(y1[-1] - goals) <= 0.35 * np.abs(goals) + 1e-9)


def test_weights_shape_the_path_but_not_the_end_point():
    theta = np.zeros((6, 8))
    theta[:, 7] = 0.4
    theta[0, :7] = 1.0
    long = ergo_jr_dmp(n_points=400)  # 10 s: the phase (and the forcing) has decayed
    y = long.normalised(theta.ravel())
    assert abs(y[:, 0] - y[:, 1]).max() > 0.1  # forcing bends joint 1's path
    assert y[-1, 0] == pytest.approx(0.4, abs=1e-2)  # the forcing fades with the phase


@pytest.mark.parametrize(
    "bad, match",
    [
        (np.full(N_PARAMS, 1.5), "must lie in"),
        (np.zeros(47), "shape"),
        (np.full(N_PARAMS, np.nan), "NaN"),
    ],
)
def test_bad_parameters_are_refused_clearly(bad, match):
    with pytest.raises(ParameterError, match=match):
        DMP.trajectory(bad)
