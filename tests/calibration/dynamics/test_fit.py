"""A short recording on the in-process twin with known non-nominal servos, and a fit that
recovers them (mujoco.sysid), checked on a held-out trajectory the fit never saw."""

from __future__ import annotations

import math

import numpy as np
import pytest

from calibration.dynamics import excitation
from calibration.dynamics.fit import delayed_control, simulate
from calibration.dynamics.recording import Recording

from .conftest import EFFECTIVE_DELAY_S, TRUTH, ratio


def test_the_excitation_stays_small_slow_and_inside_the_limits():
    from robot.spec import ergo_jr_spec

    spec = ergo_jr_spec()
    base = excitation.base_pose(spec)
    for seg in [*excitation.plan(spec, repeats=1), *excitation.plan(spec, [1])]:
        c = seg.commands
        assert np.all(c >= spec.lower) and np.all(c <= spec.upper)
        assert np.max(np.abs(c - base)) <= excitation.STEP_RAD + 1e-9
        np.testing.assert_allclose(c[0], base)  # starts and ends still at the base pose
        np.testing.assert_allclose(c[-1], base)
        if seg.name == excitation.HELD_OUT_NAME:
            speed = np.max(np.abs(np.diff(c, axis=0))) * 40.0
            assert speed < 2.5, speed  # rad/s


def test_the_recording_has_commands_and_readings_and_reads_back(truth_recording, tmp_path):
    rec = truth_recording
    assert rec.segment_names == ["m2", "m3", "held_out"] and rec.meta["complete"]
    assert len(rec.measured_t) == 5 * len(rec.command_t)  # 5 readings per 25 ms tick
    assert np.all(np.diff(rec.command_t) > 0) and np.all(np.diff(rec.measured_t) > 0)
    assert np.all(np.isfinite(rec.load))  # the twin reports its load
    back = Recording.load_file(rec.save(tmp_path / "r.npz"))
    np.testing.assert_array_equal(back.measured, rec.measured)
    assert back.segment_names == rec.segment_names and back.meta["rig_id"] == "t"
    # a bare numpy reads it too (the documented layout)
    with np.load(tmp_path / "r.npz") as z:
        assert z["command"].shape == (len(rec.command_t), 6)


def test_the_delayed_control_holds_each_command_from_its_time_plus_the_delay():
    ct = np.array([0.0, 0.025])
    cmd = np.array([[0.0], [1.0]])
    times = np.arange(0, 0.06, 0.005)
    u = delayed_control(ct, cmd, times, 0.0125, 0.005)[:, 0]
    # the step [0.035, 0.040) holds the new command half; after: all of it
    np.testing.assert_allclose(u[:7], 0.0)
    np.testing.assert_allclose(u[7], 0.5)
    np.testing.assert_allclose(u[8:], 1.0)


def test_the_fit_recovers_the_servos(truth_fit):
    r = truth_fit
    for field in ("kp", "damping", "armature"):
        err = ratio(r.servos.array(field)[1:3], TRUTH.array(field)[1:3]) - 1
        assert np.all(np.abs(err) < 0.05), (field, err)
    err = ratio(r.servos.array("frictionloss")[1:3], TRUTH.array("frictionloss")[1:3]) - 1
    assert np.all(np.abs(err) < 0.15), err
    assert abs(r.servos.delay_s - EFFECTIVE_DELAY_S) < 0.002, r.servos.delay_s
    # the joints without a segment keep the nominal servos, and say so
    np.testing.assert_allclose(r.servos.array("kp")[[0, 3, 4, 5]], 3.5)
    assert any("not recorded" in n for n in r.notes)
    lo, hi = r.intervals["kp"].T
    assert np.all(lo <= r.servos.array("kp")) and np.all(r.servos.array("kp") <= hi)


def test_the_fitted_twin_follows_the_held_out_trajectory_far_better(truth_fit):
    r = truth_fit
    assert r.held_out_rms_fitted * 5 <= r.held_out_rms_nominal, (
        math.degrees(r.held_out_rms_fitted),
        math.degrees(r.held_out_rms_nominal),
    )


def test_simulate_with_the_truth_reproduces_the_twin(truth_recording):
    ct, cmd, mt, meas = truth_recording.segment("held_out")
    pred = simulate(TRUTH.replace(delay_s=EFFECTIVE_DELAY_S), ct, cmd, mt, meas[0])
    # the twin's scene against the arm alone: the same dynamics where nothing touches (the
    # simulation starts at rest, the twin still settling from its approach: 1.4e-5 rad)
    assert np.max(np.abs(pred - meas)) < 1e-4


def test_repeats_lengthen_each_joint_segment_with_new_phases():
    from robot.spec import ergo_jr_spec

    spec = ergo_jr_spec()
    one, three = excitation.plan(spec, [2], repeats=1), excitation.plan(spec, [2], repeats=3)
    a, b = one[0].commands[:, 2], three[0].commands[:, 2]
    rate = 40.0
    repeat = round((4 * excitation.STEP_HOLD_S + excitation.SINE_S) * rate)  # 5.4 s
    assert len(b) == len(a) + 2 * repeat
    lead = len(a) - round(excitation.HOLD_S * rate)  # the first repeat as in one: the recording
    np.testing.assert_array_equal(b[:lead], a[:lead])  # checks read its steps from the start
    sine = slice(lead - round(excitation.SINE_S * rate), lead)
    later = b[sine.start + repeat : sine.stop + repeat]
    assert np.max(np.abs(later - b[sine])) > 0.05  # rad: another phase, not the same motion
    np.testing.assert_array_equal(three[1].commands, one[1].commands)  # the held-out one
    with pytest.raises(ValueError, match="repeats"):
        excitation.plan(spec, [2], repeats=0)
