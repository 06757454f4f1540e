"""Servo and drive angles <-> joint angles: the one rule for whole turns.

A servo or a drive reports the angle of its shaft (its "raw" angle, rad): a Dynamixel its
position about its centre (an XL-320: -150..150 deg), a CiA 402 drive its position actual
times 2 pi / increments per revolution (0..2 pi at power on for a single-turn absolute encoder,
any number of turns for a multi-turn one, and counted on continuously while powered). It sits
on its joint with a direction (+1 or -1) and an offset, the raw angle at the joint's zero
mark::

    raw = direction * joint + offset          (modulo whole turns)
    joint = direction * wrap(raw - offset)

A raw angle says where the shaft is only modulo whole turns, and no joint of the arm turns
by half a turn either way from its zero mark (the Ergo Jr's widest, m1 and m4, reach +-150
deg), so:

- a joint angle is the difference to the offset wrapped to (-pi, pi] (``joint_angle``);
- an offset is kept as read (``mean_angle`` of the readings at the zero mark, never wrapped:
  0..2 pi or beyond is as good as any other turn of it);
- where a conversion must be linear (a drive's targets and its position limits 0x607D are
  increments on the drive's own count), the offset is first moved by whole turns to the turn
  the drive reads now (``anchor``), so that the linear conversion and ``joint_angle`` agree
  around the joint's whole range.

Every reader of a raw angle uses these: the joint calibration (``calibration.joints``), the
arms (``robot.dynamixel.arm``, ``robot.canopen.units`` and its arm), the bus emulators
(``sim.dynamixel``, ``sim.canopen``) and the stand-ins' hidden mounting
(``sim.standin.hidden``). Pure: numpy only. Units: rad.
"""

from __future__ import annotations

import math

import numpy as np

TURN = math.tau  # one turn, rad


def wrap(angle: np.ndarray | float) -> np.ndarray:
    """Angles to (-pi, pi], same shape, rad."""
    a = np.asarray(angle, float)
    return np.pi - np.mod(np.pi - a, TURN)


def joint_angle(
    raw: np.ndarray | float, offset: np.ndarray | float, direction: np.ndarray | float = 1.0
) -> np.ndarray:
    """Raw angles -> joint angles in (-pi, pi] (broadcast shapes), rad: ``direction *
    wrap(raw - offset)``, whatever turn the raw angle and the offset are in."""
    return np.asarray(direction, float) * wrap(np.asarray(raw, float) - offset)


def raw_angle(
    joint: np.ndarray | float, offset: np.ndarray | float, direction: np.ndarray | float = 1.0
) -> np.ndarray:
    """Joint angles -> raw angles in the offset's turn (broadcast shapes), rad: ``direction *
    joint + offset`` (within half a turn of the offset for a joint inside (-pi, pi])."""
    return np.asarray(direction, float) * np.asarray(joint, float) + offset


def joint_angle_in_turn(
    raw: np.ndarray | float, offset: np.ndarray | float, direction: np.ndarray | float = 1.0
) -> np.ndarray:
    """The linear inverse of ``raw_angle`` (broadcast shapes), rad: ``direction * (raw -
    offset)``, no whole turn dropped. Where a shaft really goes: a drive follows its demand in
    increments, so a demand a turn away from where the joint is turns the joint by a turn
    (the bus emulators move the twin by it; an arm reads with ``joint_angle``)."""
    return np.asarray(direction, float) * (np.asarray(raw, float) - offset)


def anchor(offset: np.ndarray | float, raw: np.ndarray | float) -> np.ndarray:
    """The offset moved by whole turns into the turn of a raw reading (broadcast shapes), rad:
    ``raw - wrap(raw - offset)``. Then ``raw_angle`` with it is the linear inverse of
    ``joint_angle`` for every joint angle the reading's joint can take."""
    r = np.asarray(raw, float)
    return r - wrap(r - offset)


def mean_angle(samples: np.ndarray, axis: int = 0) -> np.ndarray:
    """The circular mean of raw readings along ``axis``, in the turn of the first one (never
    wrapped: an offset is kept as read), rad."""
    s = np.asarray(samples, float)
    first = np.take(s, [0], axis=axis)
    return np.squeeze(first, axis=axis) + wrap(s - first).mean(axis=axis)


def spread(samples: np.ndarray, axis: int = 0) -> np.ndarray:
    """How far apart readings of one place are along ``axis`` (largest minus smallest of their
    differences to the first, wrapped), rad."""
    s = np.asarray(samples, float)
    return np.ptp(wrap(s - np.take(s, [0], axis=axis)), axis=axis)
