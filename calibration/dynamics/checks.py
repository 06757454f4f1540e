"""What makes a recording unfit for the fit, each found before fitting and said in one line
with its fix: a recording cut short, commands sent unevenly by a host too busy, a joint that
did not move, a joint that was blocked or held at a limit, a servo held at its torque ceiling.

Thresholds (guesses, checked against the twin and the stand-in rigs, whose good recordings are
far inside them; docs/dynamics.md):
- a joint moved if its measured range over its own segment is at least ``MIN_MOVED`` of the
  commanded range (a servo with torque off, a loose horn or a dead cable moves ~0);
- a joint is blocked if, at the end of a step held ``STEP_HOLD_S``, it is more than
  ``BLOCKED_RAD`` from its command (a free servo settles within friction / kp: at most 0.012
  rad for the stand-ins' strongest friction and weakest gain);
- a servo is held at its ceiling if its load reads at least ``CEILING_LOAD`` of the maximum
  while it hardly moves (under ``STILL_RAD_S``; a free servo at its ceiling is slewing, and on
  a high-damping stand-in the multi-sine's fastest tone needs near the ceiling all along) for
  ``CEILING_S`` in a row: the excitation's steps saturate a free servo while it slews (0.35 rad
  at force_limit / damping: 0.09 s on the nominal twin, 0.21 s at the stand-ins' highest
  damping, 0.23 N.m.s/rad), and an XL-320 reports its load only every few reads (measured:
  0.3 s runs at the ceiling over the pty on stand-in 0); 0.6 s is twice that.
"""

from __future__ import annotations

import math

import numpy as np

from calibration.dynamics import excitation
from calibration.dynamics.recording import Recording, RecordingError

MIN_MOVED = 0.3
BLOCKED_RAD = 0.05
CEILING_LOAD = 0.95
CEILING_S = 0.6
# Readings further apart than this (four control ticks) leave a hole: a host that stalled (a
# loaded machine: 1.04 s measured over the pty at load 12) says nothing of the time between.
MAX_GAP_S = 0.1
# The 95th percentile of the spacing between a recording's commands may be at most this many
# control periods. Measured (docs/dynamics.md, "Bad input"): the stand-in rigs' good recordings
# over the pty at load 3-11, 27-45 ms at 40 Hz (1.1-1.8 periods); the short recording of
# tests/calibration/dynamics/test_standin.py beside 6 busy processes (load 6-11, five runs,
# tests/stress/load.py), 35-39 ms; one made while a burst of some 200 processes raised the load
# to 8, 76 ms (3.0 periods, 25 gaps over 0.1 s), and even the hidden servos' own model was 1.5
# deg off it. 2.4 lies between (a guess from that one bad recording).
MAX_SPACING_P95_PERIODS = 2.4
STILL_RAD_S = 0.2  # a tenth of the excitation's peak speeds (guess)
LIMIT_MARGIN_RAD = math.radians(2.0)  # a reading this far past a calibrated limit: at a stop


def _again(rec: Recording) -> str:
    rig = rec.meta.get("rig_id", "ID")
    return f"ergo calibrate dynamics --rig-id {rig}"


def check_recording(rec: Recording) -> None:
    """Raise a one-line ``RecordingError`` naming the first problem and its fix."""
    again = _again(rec)
    expected = [*rec.joint_names, excitation.HELD_OUT_NAME]
    missing = [s for s in rec.segment_names if s not in expected]
    if missing:
        raise RecordingError(
            f"the recording has unknown segments {missing}: record again ({again})"
        )
    got = sorted(set(rec.command_segment.tolist()))
    if not rec.meta.get("complete", False) or len(got) != len(rec.segment_names):
        done = len(got)
        raise RecordingError(
            f"the recording was cut short ({done} of {len(rec.segment_names)} segments "
            f"recorded): record again ({again}), with the arm free and the bus plugged in"
        )
    if excitation.HELD_OUT_NAME not in rec.segment_names:
        raise RecordingError(f"the recording has no held-out segment: record again ({again})")
    rate = float(rec.meta.get("control_rate_hz", 40.0))
    _check_pace(rec.command_t, rate, again)
    lower = np.asarray(rec.meta.get("lower", [-np.inf] * len(rec.joint_names)))
    upper = np.asarray(rec.meta.get("upper", [np.inf] * len(rec.joint_names)))
    for j, name in enumerate(rec.joint_names):
        if name not in rec.segment_names:
            continue
        ct, cmd, mt, meas = rec.segment(name)
        commanded = float(np.ptp(cmd[:, j]))
        moved = float(np.ptp(meas[:, j]))
        if commanded > 0 and moved < MIN_MOVED * commanded:
            raise RecordingError(
                f"{name} did not move ({math.degrees(moved):.1f} deg of "
                f"{math.degrees(commanded):.1f} deg commanded): check its torque, cable and "
                f"horn, then record again ({again})"
            )
        past = np.maximum(lower[j] - meas[:, j], meas[:, j] - upper[j])
        if np.any(past > LIMIT_MARGIN_RAD):
            raise RecordingError(
                f"{name} read {math.degrees(float(past.max())):.1f} deg past its calibrated "
                f"limit: check the joint calibration (ergo calibrate joints --rig-id "
                f"{rec.meta.get('rig_id', 'ID')}), then record again"
            )
        load = rec.segment_load(name)[:, j]
        if np.any(np.isfinite(load)) and len(mt) > 2:
            speed = np.abs(np.gradient(meas[:, j], mt))
            high = (np.abs(np.nan_to_num(load)) >= CEILING_LOAD) & (speed < STILL_RAD_S)
            longest = _longest_run(high, mt)
            if longest >= CEILING_S:
                raise RecordingError(
                    f"{name} held its torque ceiling for {longest:.1f} s: it was blocked (the "
                    f"floor, the ball, a cable) or pushed; free it and record again ({again})"
                )
        hold = round(excitation.STEP_HOLD_S * rate)
        start = round(excitation.HOLD_S * rate)
        for k in range(4):
            end = start + (k + 1) * hold - 1  # the last tick of step k
            if end >= len(ct):
                break
            t_end = ct[end] + 1.0 / rate
            i = int(np.searchsorted(mt, t_end) - 1)
            if i < 0:
                continue
            short = abs(float(meas[i, j] - cmd[end, j]))
            if short > BLOCKED_RAD:
                raise RecordingError(
                    f"{name} stopped {math.degrees(short):.1f} deg short of its command: "
                    f"blocked (the floor, the ball, a cable), at a limit or at its torque "
                    f"ceiling; free it and record again ({again})"
                )


def _check_pace(command_t: np.ndarray, rate_hz: float, again: str) -> None:
    """Refuse a recording whose commands (times ``command_t``, s, shape (C,)) were sent
    unevenly: the 95th percentile of their spacing over ``MAX_SPACING_P95_PERIODS`` control
    periods of ``rate_hz``. The host fell behind the control loop in bursts, and the jitter
    that comes with it leaves no model close to the readings."""
    if len(command_t) < 3:
        return
    spacing = np.diff(command_t)
    p95 = float(np.percentile(spacing, 95))
    if p95 > MAX_SPACING_P95_PERIODS / rate_hz:
        took = float(command_t[-1] - command_t[0])
        scheduled = (len(command_t) - 1) / rate_hz
        gaps = int(np.count_nonzero(spacing > MAX_GAP_S))
        raise RecordingError(
            f"the host fell behind the control rate: 5% of the commands came over "
            f"{p95 * 1e3:.0f} ms apart (the rate is {rate_hz:g} Hz: {1e3 / rate_hz:.0f} ms; "
            f"{gaps} gap(s) over {MAX_GAP_S * 1e3:.0f} ms; {took:.1f} s where {scheduled:.1f} s "
            f"were scheduled), too uneven a timing to fit; record again with less else running "
            f"on the machine ({again})"
        )


def _longest_run(mask: np.ndarray, t: np.ndarray, gap_s: float = MAX_GAP_S) -> float:
    """The longest time ``mask`` holds in a row, s (``t`` the sample times, s); a gap of more
    than ``gap_s`` between two readings ends a run (nothing is known of the time between)."""
    best, start = 0.0, None
    for i, m in enumerate(mask):
        if m and start is not None and t[i] - t[i - 1] > gap_s:
            best = max(best, t[i - 1] - start)
            start = t[i]
        if m and start is None:
            start = t[i]
        elif not m and start is not None:
            best = max(best, t[i] - start)
            start = None
    if start is not None:
        best = max(best, t[-1] - start)
    return float(best)
