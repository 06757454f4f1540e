"""The fit's residual of a rounded reading, the servos' goal rounding, and the block
jackknife's intervals: that they hold the truth where residuals are correlated (the textbook
ones do not), and say which parameter the data leave free."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats
from scipy.signal import lfilter

from calibration.dynamics import noise, uncertainty
from calibration.dynamics.recording import Recording, servo_goals

STEP = math.radians(300) / 1023  # an XL-320's raw unit


def test_a_rounded_reading_says_only_which_cell_the_angle_was_in():
    h, s = STEP / 2, 0.0005
    inside = noise.residual(np.array([0.0, 0.3 * h, -0.5 * h]), h, s)
    assert np.all(np.abs(inside) < 0.15)  # well inside the cell: (nearly) no residual
    assert abs(noise.residual(np.array([h]), h, s)[0]) < 1.5  # at its edge: about one sigma
    beyond = noise.residual(np.array([h + 0.0012, -h - 0.0012]), h, s)
    # beyond: at least the distance past the cell's edge over s (the Gaussian's tail, its log)
    assert 2.4 < beyond[0] < 3.2 and beyond[1] == -beyond[0]
    # a fine grid (a drive's increments, the twin): the plain error over sigma
    np.testing.assert_allclose(noise.residual(np.array([0.001, -0.0012]), 0.0, s), [2.0, -2.4])
    np.testing.assert_allclose(
        noise.residual(np.array([0.001]), 4.8e-5, s), [2.0], rtol=5e-3
    )  # CANopen's 2 pi / 65536
    # far out (a reading stamped long after it was taken): Huber's tail, the cost linear
    far = noise.residual(np.array([0.05, -0.05]), 0.0, s)
    t = noise.TAIL
    np.testing.assert_allclose(far, np.array([1, -1]) * math.sqrt(2 * t * 100 - t * t))


def test_a_moving_reading_counts_its_timing_error():
    t = np.arange(0, 1, 0.0125)
    q = np.column_stack([np.zeros_like(t), 2.0 * t])  # one still joint, one at 2 rad/s
    sd = noise.reading_sigma(t, q, timed=True)
    np.testing.assert_allclose(sd[5:-5, 0], noise.NOISE_FLOOR_RAD)
    expected = math.hypot(noise.NOISE_FLOOR_RAD, 2.0 * noise.TIMING_SD_S)
    np.testing.assert_allclose(sd[5:-5, 1], expected, rtol=1e-6)
    np.testing.assert_allclose(noise.reading_sigma(t, q, timed=False), noise.NOISE_FLOOR_RAD)


def _rec(commands: np.ndarray, readings: np.ndarray, resolution) -> Recording:
    n = commands.shape[1]
    return Recording(
        joint_names=[f"m{k + 1}" for k in range(n)], segment_names=["m1"],
        command_t=np.arange(len(commands)) * 0.025, command=commands,
        command_segment=np.zeros(len(commands), int),
        measured_t=np.arange(len(readings)) * 0.0125, measured=readings,
        load=np.full(readings.shape, np.nan), measured_segment=np.zeros(len(readings), int),
        meta={"position_resolution": resolution},
    )  # fmt: skip


def test_the_goals_are_rounded_as_the_servo_rounds_them_on_its_readings_grid():
    rng = np.random.default_rng(0)
    phase = np.array([0.0012, -0.0031])
    readings = phase + STEP * rng.integers(-200, 200, (50, 2))
    commands = rng.uniform(-0.5, 0.5, (20, 2))
    rec = _rec(commands, readings, [STEP, STEP])
    goals = servo_goals(rec)
    np.testing.assert_allclose(goals, phase + STEP * np.rint((commands - phase) / STEP))
    assert np.max(np.abs(goals - commands)) <= STEP / 2 + 1e-12
    # no resolution (the twin, a recording made before it was kept): the commands as sent
    np.testing.assert_array_equal(servo_goals(_rec(commands, readings, [0.0, 0.0])), commands)
    np.testing.assert_array_equal(servo_goals(_rec(commands, readings, None)), commands)


def _ar1(rng: np.random.Generator, n: int, phi: float) -> np.ndarray:
    """Unit-variance AR(1) noise, correlation phi between neighbours, shape (n,)."""
    e = rng.normal(size=n) * math.sqrt(1 - phi**2)
    e[0] = rng.normal()
    return lfilter([1.0], [1.0, -phi], e)


def _textbook_half(jac: np.ndarray, r: np.ndarray) -> np.ndarray:
    """mujoco.sysid.calculate_intervals' half widths: s^2 (J'J)^-1, t quantile."""
    n, p = jac.shape
    s2 = r @ r / (n - p)
    return stats.t.ppf(0.975, n - p) * np.sqrt(s2 * np.diag(np.linalg.inv(jac.T @ jac)))


@pytest.mark.parametrize("phi", [0.97])
def test_the_jackknife_holds_the_truth_where_residuals_are_correlated(phi):
    """Six segments of 512 readings, each with its own regressors (as each joint's segment
    carries its own parameters), noise correlated over ~30 readings: the jackknife's 95 %
    intervals hold the truth about 95 % of the time; the textbook ones far less."""
    rng = np.random.default_rng(1)
    segments, m, p = 6, 512, 3
    t = np.arange(m) * 0.0125
    held_jk = held_tb = total = 0
    for _ in range(60):
        rows, blocks = [], []
        for k in range(segments):
            x = np.zeros((m, p))
            x[:, 0] = np.sin(2 * np.pi * (0.4 + 0.2 * k) * t)
            x[:, 1] = np.where(t % 1.6 < 0.8, 1.0, -1.0) * (k % 2 == 0)
            x[:, 2] = np.cos(2 * np.pi * 1.1 * t) * (k % 2 == 1)
            rows.append(x)
            blocks.append(uncertainty.block_ids(t) + 100 * k)
        jac = np.vstack(rows)
        r = np.concatenate([_ar1(rng, m, phi) for _ in range(segments)])
        est = np.linalg.lstsq(jac, r, rcond=None)[0]  # the truth is 0
        res = r - jac @ est
        lin = uncertainty.Linearisation(["a", "b", "c"], jac, res, np.concatenate(blocks))
        iv = uncertainty.jackknife(lin)
        held_jk += int(np.sum(np.abs(est) <= iv.half))
        held_tb += int(np.sum(np.abs(est) <= _textbook_half(jac, res)))
        total += p
    assert held_jk / total >= 0.88, held_jk / total
    assert held_tb / total <= 0.6, held_tb / total  # the textbook intervals miss


def test_a_parameter_the_data_leave_free_is_said_to_be_unidentified():
    rng = np.random.default_rng(2)
    t = np.arange(2048) * 0.0125
    jac = np.column_stack([np.sin(3 * t), 1e-4 * np.cos(7 * t), np.sign(np.sin(t))])
    r = _ar1(rng, len(t), 0.9) * 0.1
    lin = uncertainty.Linearisation(
        ["m1.kp", "m1.armature", "delay"], jac, r, uncertainty.block_ids(t)
    )
    iv = uncertainty.jackknife(lin)
    why = uncertainty.identification(iv, {"m1.kp": (-1.8, 1.8), "m1.armature": (-2.3, 2.3)})
    assert why["m1.kp"].identified and not why["m1.kp"].reason
    assert not why["m1.armature"].identified
    assert "does not pin it" in why["m1.armature"].reason
    assert "wider than the fit's bounds" in why["m1.armature"].reason
    assert "delay" not in why


def test_the_models_mismatch_widens_a_bus_interval_never_the_twins():
    z = stats.norm.ppf(0.975)
    for field in ("kp", "damping", "armature", "frictionloss"):
        assert uncertainty.with_mismatch(0.05, "twin", field) == 0.05  # the twin is the model
        sds = {bus: uncertainty.MISMATCH_SD[bus][field] for bus in ("dynamixel", "canopen")}
        for bus, sd in sds.items():
            assert sd > 0.0
            # in quadrature: a narrow jackknife interval becomes the mismatch's, a wide one
            # stays about as it was
            assert uncertainty.with_mismatch(0.0, bus, field) == pytest.approx(z * sd)
            wide = uncertainty.with_mismatch(1.0, bus, field)
            assert 1.0 < wide < 1.0 + (z * sd) ** 2
        # a bus not measured: the larger of the two
        assert uncertainty.with_mismatch(0.0, "other", field) == pytest.approx(
            z * max(sds.values())
        )
