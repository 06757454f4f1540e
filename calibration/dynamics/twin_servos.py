"""The servos a rig's twin is built with: the rig's fitted ``dynamics.json`` when there is one
(``ergo calibrate dynamics``), else the nominal twin's (None)."""

from __future__ import annotations

from pathlib import Path

from calibration.store import CalibrationMissing, calibration_path, load_file
from sim.servo_model import ServoModel


def fitted_servos(
    rig_id: str, directory: str | Path | None = None
) -> tuple[ServoModel | None, Path | None]:
    """(servo model, file) of rig ``rig_id``'s dynamics calibration, or (None, None) without
    one; a damaged or foreign file raises a one-line ``CalibrationError`` naming it."""
    path = calibration_path("dynamics", rig_id, directory)
    try:
        data = load_file(path, "dynamics")
    except CalibrationMissing:
        return None, None
    return ServoModel.from_dict(data["servos"]), path
