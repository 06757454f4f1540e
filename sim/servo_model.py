"""The twin's servo dynamics as data: per-joint position gain, damping, armature, friction loss,
torque ceiling, and the command transport delay.

One ``ServoModel`` says how the twin's six servos move. ``NOMINAL`` is the hand-set model of
``sim/models/ergo_jr.xml`` (its README says where each number comes from); a system
identification of a user's arm (``ergo calibrate dynamics``) or a stand-in rig's hidden servos
give others. ``Twin(servos=...)`` builds its servos from one. A rig's fitted servos are its
``dynamics.json`` calibration (``<root>/<rig_id>/dynamics.json``, ``robot/calibration_files.py``):
``check_dynamics`` is that payload's check (``calibration/store.py`` validates through it) and
``fitted_servos`` reads it, from a rig's resolved ``RigCalibration``, for the twin (``--rig sim
--rig-id X``, the Gymnasium environments, ``ergo twin serve --rig-id X``).

MuJoCo mapping (position actuator on a hinge joint, MJCF reference):
- ``kp``: actuator ``gainprm[0]`` and ``-biasprm[1]`` (torque = kp * (target - q)), N.m/rad;
- ``damping``: ``dof_damping``, N.m.s/rad; ``armature``: ``dof_armature``, kg.m^2;
- ``frictionloss``: ``dof_frictionloss`` (dry friction), N.m;
- ``force_limit``: ``actuator_forcerange`` = [-force_limit, +force_limit], N.m;
- ``delay_s``: a command reaches the actuators this long after it is given, s (``Twin``
  holds it in a queue; MuJoCo has no transport delay of its own).

Units: N.m, rad, s, kg.m^2. Every array has shape (6,), in ``robot.spec.ERGO_JR_JOINTS`` order.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np

from plumbing.fields import Fields, is_matrix
from robot.calibration_files import (
    CalibrationError,
    CalibrationMissing,
    RigCalibration,
    read_document,
)

N_JOINTS = 6
# The per-joint fields, in the order reports and fits list them.
PER_JOINT = ("kp", "damping", "armature", "frictionloss", "force_limit")
# A command delay longer than this is no servo's (guess: ten 40 Hz control ticks).
MAX_DELAY_S = 0.25


class ServoModelError(ValueError):
    """A servo model with a wrong shape or a value out of range; the message is one line."""


@dataclass(frozen=True)
class ServoModel:
    """Servo dynamics of the six joints (see the module docstring for units and mapping).

    Attributes:
        kp, damping, armature, frictionloss, force_limit: per joint, shape (6,).
        delay_s: command transport delay, s (>= 0).
    """

    kp: tuple[float, ...]
    damping: tuple[float, ...]
    armature: tuple[float, ...]
    frictionloss: tuple[float, ...]
    force_limit: tuple[float, ...]
    delay_s: float = 0.0

    def __post_init__(self) -> None:
        for name in PER_JOINT:
            value = getattr(self, name)
            try:
                arr = np.asarray(value, dtype=float).reshape(-1)
            except (TypeError, ValueError):
                raise ServoModelError(
                    f"servo model: {name} must be numbers, got {value!r}"
                ) from None
            if arr.shape != (N_JOINTS,):
                raise ServoModelError(
                    f"servo model: {name} needs {N_JOINTS} values, got {arr.size}"
                )
            if not np.all(np.isfinite(arr)):
                raise ServoModelError(f"servo model: {name} must be finite, got {arr.tolist()}")
            strictly = name in ("kp", "force_limit")
            if np.any(arr <= 0.0) if strictly else np.any(arr < 0.0):
                sign = "> 0" if strictly else ">= 0"
                raise ServoModelError(f"servo model: {name} must be {sign}, got {arr.tolist()}")
            object.__setattr__(self, name, tuple(float(v) for v in arr))
        delay = self.delay_s
        if (
            not isinstance(delay, int | float)
            or not math.isfinite(delay)
            or not (0.0 <= delay <= MAX_DELAY_S)
        ):
            raise ServoModelError(
                f"servo model: delay_s must be a number in [0, {MAX_DELAY_S}] s, got {delay!r}"
            )
        object.__setattr__(self, "delay_s", float(delay))

    def array(self, name: str) -> np.ndarray:
        """One per-joint field as a float array, shape (6,)."""
        if name not in PER_JOINT:
            raise ServoModelError(f"servo model: no per-joint field {name!r}")
        return np.asarray(getattr(self, name), dtype=float)

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-able dict (lists of floats)."""
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(self).items()}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> ServoModel:
        """The inverse of ``to_dict``; unknown or missing fields are one-line errors."""
        if not isinstance(data, Mapping):
            raise ServoModelError(f"servo model must be an object, got {type(data).__name__}")
        names = {f.name for f in fields(cls)}
        unknown = sorted(set(data) - names)
        if unknown:
            raise ServoModelError(f"servo model: unknown field(s) {', '.join(unknown)}")
        missing = [n for n in PER_JOINT if n not in data]
        if missing:
            raise ServoModelError(f"servo model: missing field(s) {', '.join(missing)}")
        return cls(**dict(data))

    def replace(self, **changes: Sequence[float] | float) -> ServoModel:
        """A copy with some fields changed (validated)."""
        return ServoModel(**{**self.to_dict(), **changes})


# The hand-set servos of sim/models/ergo_jr.xml (default class "ergo"): kp 3.5 N.m/rad and
# damping 0.1 N.m.s/rad measured on the model for a 0.2 s 30-degree step, force limit 0.39 N.m
# the XL-320's stall torque at 7.4 V (ROBOTIS datasheet), armature 0.0005 kg.m^2 and friction
# loss 0.001 N.m guesses (sim/models/README.md). No transport delay. tests/sim/test_servo_model.py
# checks that this equals what the MJCF file loads.
NOMINAL = ServoModel(
    kp=(3.5,) * N_JOINTS,
    damping=(0.1,) * N_JOINTS,
    armature=(0.0005,) * N_JOINTS,
    frictionloss=(0.001,) * N_JOINTS,
    force_limit=(0.39,) * N_JOINTS,
    delay_s=0.0,
)


def read_model(model: Any, act_idx: np.ndarray, dof_idx: np.ndarray) -> ServoModel:
    """The servo model a loaded ``mujoco.MjModel`` holds (no delay: MuJoCo has none).

    Args:
        model: the MjModel.
        act_idx: the six position actuators' ids, shape (6,).
        dof_idx: the six joints' dof addresses, shape (6,).
    """
    return ServoModel(
        kp=tuple(model.actuator_gainprm[act_idx, 0]),
        damping=tuple(model.dof_damping[dof_idx]),
        armature=tuple(model.dof_armature[dof_idx]),
        frictionloss=tuple(model.dof_frictionloss[dof_idx]),
        force_limit=tuple(model.actuator_forcerange[act_idx, 1]),
    )


def write_model(model: Any, act_idx: np.ndarray, dof_idx: np.ndarray, servos: ServoModel) -> None:
    """Set a loaded ``mujoco.MjModel``'s servos to ``servos`` (torque on: full gains).

    Args: as ``read_model``; ``servos`` the model to write (its delay is the ``Twin``'s).
    """
    kp = servos.array("kp")
    model.actuator_gainprm[act_idx, 0] = kp
    model.actuator_biasprm[act_idx, 0] = 0.0
    model.actuator_biasprm[act_idx, 1] = -kp
    model.dof_damping[dof_idx] = servos.array("damping")
    model.dof_armature[dof_idx] = servos.array("armature")
    model.dof_frictionloss[dof_idx] = servos.array("frictionloss")
    limit = servos.array("force_limit")
    model.actuator_forcerange[act_idx, 0] = -limit
    model.actuator_forcerange[act_idx, 1] = limit


# ---- a rig's fitted servos (its dynamics.json) --------------------------------------------
# A rig's fitted servos (its dynamics.json) stay within these factors of NOMINAL's, per field
# (guesses: a decade around the nominal XL-320 either way, wider than the fit's own bounds,
# calibration/dynamics/fit.py RATIO_BOUNDS, so that every fit passes; the force limit up to
# 10 x the XL-320's 0.39 N.m stall torque, about an XM430's 4.1 N.m; the friction loss from 0,
# up to 0.1 N.m, a quarter of the stall torque). What is out of them is a damaged file, not a
# servo: kp = 1e300 would make the twin's physics blow up.
PAYLOAD_RATIO_BOUNDS = {
    "kp": (0.1, 10.0),
    "damping": (0.1, 10.0),
    "armature": (0.05, 20.0),
    "frictionloss": (0.0, 100.0),
    "force_limit": (0.1, 10.5),
}


def check_dynamics(c: Fields) -> ServoModel:
    """Check a dynamics calibration's payload (``ergo calibrate dynamics``: ``servos``, the
    ``recording`` fitted, the ``held_out_rms_rad``); returns its servo model. A bad field is a
    one-line ``CalibrationError`` naming it."""
    try:
        servos = ServoModel.from_dict(c.get("servos"))
    except ServoModelError as exc:
        c.fail("servos", f"is not a servo model ({exc})")
    for name, (lo, hi) in PAYLOAD_RATIO_BOUNDS.items():
        arr, nominal = servos.array(name), NOMINAL.array(name)
        if np.any(arr < lo * nominal) or np.any(arr > hi * nominal):
            c.fail(
                "servos",
                f"{name} must be within [{lo * nominal[0]:g}, {hi * nominal[0]:g}] "
                f"({lo:g}-{hi:g} x the nominal twin's, sim/servo_model.py), got {arr.tolist()}",
            )
    rec = c.get("recording")
    if not isinstance(rec, dict) or not isinstance(rec.get("sha256"), str):
        c.fail("recording", "must name the recording fitted (path, sha256)")
    rms = c.get("held_out_rms_rad")
    if not isinstance(rms, dict) or not all(
        is_matrix(rms.get(k), ()) for k in ("nominal", "fitted")
    ):
        c.fail("held_out_rms_rad", "must hold the held-out RMS errors nominal and fitted, rad")
    return servos


def fitted_servos(calibration: RigCalibration) -> tuple[ServoModel | None, Path]:
    """(servo model, file) of a rig's dynamics calibration (``calibration.dynamics``), or
    (None, the file looked for) without one; a damaged or foreign file raises a one-line
    ``CalibrationError`` naming it."""
    path = calibration.dynamics
    try:
        doc = read_document(path, "dynamics")
    except CalibrationMissing:
        return None, path
    data = Fields(f"{path}: data", doc["data"], CalibrationError, name="data")
    return check_dynamics(data), path
