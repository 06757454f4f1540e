"""Bad input to the servo fit, each one line naming the fix: a recording cut short, a joint
that did not move, a servo blocked at its torque ceiling, a fit the data cannot reach."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from calibration.dynamics.checks import check_recording
from calibration.dynamics.fit import FitError, fit
from calibration.dynamics.recording import RecordingError
from sim.servo_model import NOMINAL

from .conftest import TRUTH, record_on

# Gauss-Newton iterations of the refused fit: a few move the servos off the nominal ones that
# made the spliced held-out motion, which is all the refusal needs (the full fit: 40)
FEW_ITERS = 3


class StopAfter:
    """A clock that raises KeyboardInterrupt (Ctrl-C) after ``n`` advances."""

    def __init__(self, clock, n: int) -> None:
        self.clock, self.n = clock, n

    def now(self) -> float:
        return self.clock.now()

    def advance(self, seconds: float) -> None:
        self.n -= 1
        if self.n < 0:
            raise KeyboardInterrupt
        self.clock.advance(seconds)


def test_a_recording_cut_short_says_where_and_keeps_the_part():
    with pytest.raises(RecordingError, match=r"cut short in segment m3 .* \(interrupted\)") as e:
        record_on(TRUTH, clock_hook=lambda c: StopAfter(c, 2500))
    partial = e.value.partial
    assert partial is not None and not partial.meta["complete"]
    with pytest.raises(
        RecordingError, match=r"cut short \(2 of 3 segments recorded\): record again"
    ):
        check_recording(partial)


def test_a_joint_that_did_not_move():
    def ignore_m3(twin) -> None:
        """m3's servo ignores its goals (a servo in alarm, as after an overload shutdown)."""
        given = twin.set_targets

        def set_targets(q):
            q = np.array(q, float)
            q[2] = twin.joint_positions()[2]
            given(q)

        twin.set_targets = set_targets

    with pytest.raises(
        RecordingError, match=r"^m3 did not move \(\d+\.\d deg of 40\.1 deg commanded\): check"
    ):
        check_recording(record_on(NOMINAL, arm_hook=ignore_m3))


def test_a_servo_held_at_its_torque_ceiling():
    from robot.watchdog import Watchdog

    weak = NOMINAL.replace(force_limit=(0.39, 0.012, 0.39, 0.39, 0.39, 0.39))  # cannot lift m2
    # the arm's own watchdog stops a servo held at its ceiling for 2 s: torque off, cut short
    with pytest.raises(RecordingError, match=r"cut short in segment m2 .*SafetyStop.*torque off"):
        record_on(weak)
    # a shorter hold (a watchdog that lets it go on) is refused by the check before any fit
    rec = record_on(weak, watchdog=Watchdog(hold_s=30.0))
    with pytest.raises(RecordingError, match=r"^m2 held its torque ceiling for \d+\.\d s: it was"):
        check_recording(rec)


def test_a_good_recording_passes(truth_recording):
    check_recording(truth_recording)


def test_a_fit_that_does_not_reach_the_held_out_motion_is_refused(truth_recording):
    # the held-out motion of another arm (the nominal twin): what the fit learnt from the
    # training segments makes it worse there, and the fit says so
    other = record_on(NOMINAL)
    spliced = copy.deepcopy(truth_recording)
    k = spliced.segment_names.index("held_out")
    mask = spliced.measured_segment == k
    np.testing.assert_array_equal(spliced.measured_t[mask], other.measured_t[mask])
    spliced.measured[mask] = other.measured[mask]
    with pytest.raises(FitError, match=r"no closer to the arm than the nominal one"):
        fit(spliced, max_iters=FEW_ITERS)


def test_a_hole_in_the_readings_ends_a_run_at_the_ceiling():
    from calibration.dynamics.checks import _longest_run

    held = np.array([1, 1, 1, 1, 1, 0], bool)
    stalled = np.array([0.0, 0.1, 0.2, 1.2, 1.3, 1.4])  # the host stalled 1 s after 0.2 s
    assert _longest_run(held, stalled) == pytest.approx(0.2)
    steady = np.array([0.0, 0.05, 0.1, 0.15, 0.2, 0.25])
    assert _longest_run(held, steady) == pytest.approx(0.25)


def test_a_recording_made_while_the_host_fell_behind_is_refused(truth_recording):
    # a load burst: every tenth tick the loop stalls 80 ms, then catches up 20 ms a tick (the
    # next ticks 5 ms apart); the readings then say little of when each command reached the
    # servos
    late = copy.deepcopy(truth_recording)
    behind = np.array([0.08, 0.06, 0.04, 0.02, 0, 0, 0, 0, 0, 0])
    late.command_t = late.command_t + np.resize(behind, len(late.command_t))
    with pytest.raises(
        RecordingError,
        match=r"^the host fell behind the control rate: 5% of the commands came over 105 ms "
        r"apart \(the rate is 40 Hz: 25 ms; 67 gap\(s\) over 100 ms; 16\.8 s where 16\.8 s were "
        r"scheduled\), too uneven a timing to fit; record again with less else running on the "
        r"machine \(ergo calibrate dynamics --rig-id t\)$",
    ):
        check_recording(late)
    # uniformly slower, as a loaded host (load 6-10: 11 % late, no spacing over 2 periods):
    # kept; the jitter, not the pace, spoils a fit
    slow = copy.deepcopy(truth_recording)
    slow.command_t = slow.command_t * 1.15
    slow.measured_t = slow.measured_t * 1.15
    check_recording(slow)
