"""One reading of all joints (``JointState``): what every arm's ``read`` returns and the
watchdog checks; its own module so that ``robot.arm`` and ``robot.watchdog`` both import it
and neither the other."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class JointState:
    """One reading of all joints.

    Attributes:
        positions: shape (n,), rad.
        velocities: shape (n,), rad/s.
        loads: shape (n,), signed fraction of the maximum torque (NaN if unknown).
        temperatures: shape (n,), degrees C (NaN if unknown).
        errors: shape (n,), backend error flags per joint, 0 when healthy.
        timestamp: when the positions were sampled, as near as the backend knows, s on the
            arm's clock: the twin's time; over Dynamixel when the read request left the
            host; over CANopen when the SYNC the drives sampled them at did.
    """

    positions: np.ndarray
    velocities: np.ndarray
    loads: np.ndarray
    temperatures: np.ndarray
    errors: np.ndarray
    timestamp: float

    @classmethod
    def from_positions(
        cls, positions: np.ndarray, timestamp: float, **kw: np.ndarray
    ) -> JointState:
        """A state with only positions known (others zero or NaN unless given)."""
        n = len(positions)
        # defaults made only for what is missing (an arm reads this every control tick)
        return cls(
            positions=np.asarray(positions, dtype=float),
            velocities=kw["velocities"] if "velocities" in kw else np.zeros(n),
            loads=kw["loads"] if "loads" in kw else np.full(n, np.nan),
            temperatures=kw["temperatures"] if "temperatures" in kw else np.full(n, np.nan),
            errors=kw["errors"] if "errors" in kw else np.zeros(n, dtype=int),
            timestamp=timestamp,
        )
