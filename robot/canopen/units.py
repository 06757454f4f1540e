"""Joint angles (rad) <-> drive position increments (counts).

A drive reports positions in encoder increments; 0x608F "position encoder resolution" gives
increments per motor revolution (sub 1 increments / sub 2 revolutions, CiA 402-2). Each joint
also has a direction (+1 or -1, how the drive is mounted) and an offset (joint angle at drive
position 0):

    q = offset + direction * counts * 2 pi / counts_per_rev

modulo whole turns (``robot.angles``, the rule every arm shares): ``to_rad`` wraps the joint
angle to (-pi, pi] whatever turn the drive counts in; ``to_counts`` and ``limits_to_counts``
are linear, in the turn of the offset, so an arm first moves the offsets by whole turns to the
turn its drives read (``anchored``): a single-turn absolute encoder reads 0..2 pi at power on,
a multi-turn one any number of turns.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from robot.angles import anchor, joint_angle, raw_angle

INT32_MIN = -(2**31)
INT32_MAX = 2**31 - 1


class UnitsError(ValueError):
    """A scaling is invalid or a position does not fit the drive's 32-bit range."""


@dataclass(frozen=True)
class JointScaling:
    """Per-joint conversion.

    Attributes:
        counts_per_rev: increments per revolution, shape (n,), > 0.
        directions: +1 or -1, shape (n,).
        offsets: joint angle at 0 increments, shape (n,), rad.
    """

    counts_per_rev: np.ndarray
    directions: np.ndarray
    offsets: np.ndarray

    def __post_init__(self) -> None:
        cpr = np.asarray(self.counts_per_rev, dtype=float).reshape(-1)
        n = cpr.size
        d = np.asarray(self.directions, dtype=float).reshape(-1)
        o = np.asarray(self.offsets, dtype=float).reshape(-1)
        if d.size != n or o.size != n:
            raise UnitsError(
                f"scaling sizes differ: {n} resolutions, {d.size} directions, {o.size} offsets"
            )
        if not np.all(np.isfinite(cpr)) or np.any(cpr <= 0):
            raise UnitsError(f"counts per revolution must be positive, got {cpr.tolist()}")
        if not np.all(np.isin(d, (-1.0, 1.0))):
            raise UnitsError(f"directions must be +1 or -1, got {d.tolist()}")
        if not np.all(np.isfinite(o)):
            raise UnitsError(f"offsets must be finite, got {o.tolist()}")
        object.__setattr__(self, "counts_per_rev", cpr)
        object.__setattr__(self, "directions", d)
        object.__setattr__(self, "offsets", o)

    @property
    def n(self) -> int:
        return int(self.counts_per_rev.size)

    @property
    def drive_offsets(self) -> np.ndarray:
        """The drive's angle at joint zero (``robot.angles``' offset), shape (n,), rad."""
        return -self.directions * self.offsets

    def to_counts(self, q: np.ndarray) -> np.ndarray:
        """Joint angles, shape (n,), rad -> increments in the offsets' turn, shape (n,), int64
        within int32."""
        q = np.asarray(q, dtype=float).reshape(self.n)
        drive = raw_angle(q, self.drive_offsets, self.directions)
        counts = np.rint(drive * self.counts_per_rev / math.tau)
        if np.any(counts < INT32_MIN) or np.any(counts > INT32_MAX):
            raise UnitsError(f"position {q.tolist()} rad does not fit the drives' 32-bit range")
        return counts.astype(np.int64)

    def to_rad(self, counts: np.ndarray) -> np.ndarray:
        """Increments, shape (n,) -> joint angles in (-pi, pi], shape (n,), rad."""
        c = np.asarray(counts, dtype=float).reshape(self.n)
        drive = c * math.tau / self.counts_per_rev
        return joint_angle(drive, self.drive_offsets, self.directions)

    def anchored(self, counts: np.ndarray) -> JointScaling:
        """This scaling with each offset moved by whole turns to the turn of the drives'
        readings ``counts``, shape (n,) (``robot.angles.anchor``): its ``to_counts`` and
        ``limits_to_counts`` are then the drive's own increments around where it is."""
        drive = np.asarray(counts, dtype=float).reshape(self.n) * math.tau / self.counts_per_rev
        moved = anchor(self.drive_offsets, drive)
        return JointScaling(self.counts_per_rev, self.directions, -self.directions * moved)

    def limits_to_counts(self, lower: np.ndarray, upper: np.ndarray) -> tuple[np.ndarray, ...]:
        """Joint limits (rad) -> (min, max) increments per joint (swapped where direction is
        -1), shape (n,) each."""
        a, b = self.to_counts(lower), self.to_counts(upper)
        return np.minimum(a, b), np.maximum(a, b)
