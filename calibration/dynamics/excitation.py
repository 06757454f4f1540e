"""Excitation trajectories for identifying the servos: per joint, steps then a multi-sine,
around a base pose, with the other joints held; and a held-out multi-sine on all joints at once.

Why these (docs/dynamics.md):
- steps of ``STEP_RAD`` (0.35 rad, 20 deg): the safety clamp turns them into 0.15 rad-per-tick
  ramps, so the servo's error exceeds its torque ceiling (0.15 rad x kp 3.5 N.m/rad = 0.53 N.m >
  0.39 N.m, the XL-320's stall torque): the joint slews at the speed where damping eats the
  ceiling (force_limit / damping), which tells damping from gain; the settling after it tells
  the gain, the friction's dead band and the delay;
- a multi-sine of three tones (0.4, 1.1 and 2.7 Hz; co-prime-ish so no harmonic coincides) of
  ``SINE_RAD`` in all: continuous motion at a few rad/s, where damping and friction differ;
- the held-out trajectory plays other tones (0.6, 1.7 Hz) on every joint together, with other
  phases, so it tests the fit on motion it never saw, and the joints' coupling.

Small and slow enough for a desk arm: the base pose holds the tool tip 0.3 m above the floor
(the twin: 0.306 m), far above the ball (radius 0.02 m) and the wall; every excursion is at most
0.35 rad from it, peak commanded speeds stay under 2.5 rad/s (a fifth of the XL-320's no-load
11.9 rad/s, ROBOTIS datasheet), every command still goes through ``robot.Arm``'s clamp (joint
limits and 0.15 rad per tick) and the joint calibration's limits. Guesses (tuned on the twin):
the amplitudes, tones and durations.

Units: rad, s. A plan is sampled at the control rate (``robot.spec.CONTROL_RATE_HZ``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robot.spec import CONTROL_RATE_HZ, ArmSpec

# The base pose: m2 leans 0.3 rad forward, m3 folds 0.6 rad back, m5 0.4 rad: the tip 0.306 m
# above the floor and 5 mm from the axis of m1 on the twin (measured); gravity loads m2, m3, m5.
BASE_POSE = (0.0, 0.3, -0.6, 0.0, 0.4, 0.0)
STEP_RAD = 0.35
STEP_HOLD_S = 0.6  # each step held this long: the servo settles in ~0.2 s (docs/twin.md)
SINE_RAD = 0.25  # the multi-sine's tones sum to at most this
SINE_TONES_HZ = (0.4, 1.1, 2.7)
SINE_S = 3.0
HELD_OUT_TONES_HZ = (0.6, 1.7)
HELD_OUT_S = 3.0
HELD_OUT_NAME = "held_out"
HOLD_S = 0.5  # the base pose held before each segment: the arm starts still
# How many times a recording plays each joint's steps and multi-sine (``ergo calibrate
# dynamics --repeats``). Measured on stand-ins 213-215 over both buses
# (docs/results_dynamics.md): with three (107 s in all; eleven jackknife blocks a joint
# against four) 137 of 144 values identified against 102 with one (42 s), the intervals
# (with the model's mismatch, ``uncertainty.MISMATCH_SD``) a median 25.6 % of their value
# against 51.9 %; the mismatch is what is left, and a longer recording does not shrink it.
REPEATS = 3
# Each further repeat of a joint's steps and multi-sine plays the tones at other phases (rad,
# per repeat; a guess: far from a multiple of 2 pi for every tone's multiple).
REPEAT_PHASE = 1.3


@dataclass(frozen=True)
class Segment:
    """One excitation segment: commands at the control rate, starting and ending at the base.

    Attributes:
        name: the joint excited (``m1`` .. ``m6``), or ``held_out``.
        commands: shape (T, n), rad.
    """

    name: str
    commands: np.ndarray


def _multisine(
    t: np.ndarray, tones: tuple[float, ...], amplitude: float, phase: float
) -> np.ndarray:
    """Sum of sines of ``tones`` (Hz) with equal amplitudes summing to ``amplitude`` (rad),
    faded in and out over 0.5 s so that it starts and ends at 0 with zero speed; shape (T,)."""
    a = amplitude / len(tones)
    y = sum(a * np.sin(2 * np.pi * f * t + phase * (k + 1)) for k, f in enumerate(tones))
    duration = t[-1] if len(t) else 0.0
    fade = np.clip(np.minimum(t, duration - t) / 0.5, 0.0, 1.0)
    fade = 0.5 - 0.5 * np.cos(np.pi * fade)
    return y * fade


def base_pose(spec: ArmSpec) -> np.ndarray:
    """``BASE_POSE`` inside the spec's limits (a calibrated arm's may be narrower), shape (n,)."""
    return np.clip(np.asarray(BASE_POSE, float), spec.lower, spec.upper)


def joint_segment(
    spec: ArmSpec, joint: int, rate_hz: float = CONTROL_RATE_HZ, repeats: int = REPEATS
) -> Segment:
    """Steps then a multi-sine on one joint, the others at the base pose; with ``repeats`` > 1
    the steps and the multi-sine are played that many times in a row, each repeat's tones at
    other phases (``REPEAT_PHASE``): a longer segment, more blocks of the intervals' jackknife
    (``calibration.dynamics.uncertainty``). 5.4 s a repeat, plus 1 s of holds."""
    if repeats < 1:
        raise ValueError(f"repeats must be at least 1, got {repeats}")
    base = base_pose(spec)
    dt = 1.0 / rate_hz
    hold = np.zeros(round(HOLD_S * rate_hz))
    levels = (STEP_RAD, 0.0, -STEP_RAD, 0.0)
    steps = np.concatenate([np.full(round(STEP_HOLD_S * rate_hz), v) for v in levels])
    t = np.arange(round(SINE_S * rate_hz)) * dt
    played = [
        part
        for r in range(repeats)
        for part in (
            steps,
            _multisine(t, SINE_TONES_HZ, SINE_RAD, phase=0.3 * (joint + 1) + REPEAT_PHASE * r),
        )
    ]
    offset = np.concatenate([hold, *played, hold])
    commands = np.tile(base, (len(offset), 1))
    commands[:, joint] = np.clip(base[joint] + offset, spec.lower[joint], spec.upper[joint])
    return Segment(spec.names[joint], commands)


def held_out_segment(spec: ArmSpec, rate_hz: float = CONTROL_RATE_HZ) -> Segment:
    """Other tones on every joint together (the fit never sees it)."""
    base = base_pose(spec)
    t = np.arange(round(HELD_OUT_S * rate_hz)) / rate_hz
    hold = np.tile(base, (round(HOLD_S * rate_hz), 1))
    moving = np.stack(
        [
            base[j] + _multisine(t, HELD_OUT_TONES_HZ, SINE_RAD, phase=1.1 + 0.7 * j)
            for j in range(spec.n)
        ],
        axis=1,
    )
    commands = np.clip(np.concatenate([hold, moving, hold]), spec.lower, spec.upper)
    return Segment(HELD_OUT_NAME, commands)


def plan(spec: ArmSpec, joints: list[int] | None = None, repeats: int = REPEATS) -> list[Segment]:
    """The whole recording: one segment per joint (all by default; each with ``repeats`` of
    its steps and multi-sine), then the held-out one."""
    chosen = list(range(spec.n)) if joints is None else joints
    return [joint_segment(spec, j, repeats=repeats) for j in chosen] + [held_out_segment(spec)]
