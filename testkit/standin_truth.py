"""Reads a stand-in rig's hidden parameters back (the file ``ergo twin serve --stand-in SEED``
writes): the truth that tests, bench and experiment scripts compare a calibration against.

Nothing but tests/, bench/ and experiments/ may import this module
(tests/sim/standin/test_secrecy.py reads every import of the project's source to check it): a
calibration that read the truth would prove nothing.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from robot.angles import wrap
from sim.servo_model import ServoModel, ServoModelError
from sim.standin.hidden import HiddenCamera, HiddenRig, StandinError


def read_hidden(path: str | os.PathLike[str]) -> HiddenRig:
    """The hidden parameters in ``path`` (written by ``sim.standin.hidden.write_hidden``).

    Raises:
        StandinError: a missing or damaged file (one line naming it).
    """
    path = Path(path)
    try:
        data = json.loads(path.read_text())
        joints, camera = data["joints"], data["camera"]
        return HiddenRig(
            seed=data["seed"],
            directions=np.asarray(joints["directions"], float),
            offsets=np.asarray(joints["offsets_rad"], float),
            camera=HiddenCamera(
                size=(int(camera["size"][0]), int(camera["size"][1])),
                camera_matrix=np.asarray(camera["camera_matrix"], float),
                dist_coeffs=np.asarray(camera["dist_coeffs"], float),
                position=np.asarray(camera["position"], float),
                rotation=np.asarray(camera["rotation"], float),
            ),
            servos=ServoModel.from_dict(data["servos"]),
            ball_xy=(float(data["ball_xy"][0]), float(data["ball_xy"][1])),
            can_zero_marks=np.asarray(
                joints.get("canopen_zero_marks_rad", joints["offsets_rad"]), float
            ),
        )
    except OSError as exc:
        raise StandinError(f"cannot read the hidden parameters {path}: {exc}") from None
    except (ValueError, KeyError, TypeError, IndexError, ServoModelError) as exc:
        raise StandinError(f"{path} is not a stand-in's hidden file: {exc!r}") from None


# ---- what a calibration recovered, against the truth --------------------------------------
def joint_errors(
    hidden: HiddenRig, joints: dict, bus: str = "dynamixel"
) -> tuple[np.ndarray, bool]:
    """A joints.json's ``data`` against the hidden mounting of ``bus`` (``"dynamixel"``: the
    servos' offsets; ``"canopen"``: the drives' zero marks): per joint, the offset's error
    (deg, modulo whole turns, shape (6,)), and whether every direction is right."""
    offsets = np.asarray(joints["offsets"], float)
    truth = hidden.can_offsets if bus == "canopen" else hidden.offsets
    err = np.degrees(np.abs(wrap(offsets - truth)))
    return err, bool(np.array_equal(np.asarray(joints["directions"], float), hidden.directions))


def camera_errors(hidden: HiddenRig, camera: dict) -> dict[str, float]:
    """A camera.json's ``data`` against the hidden lens: fx and fy errors (relative), the
    principal point's (px, and its distance)."""
    k = np.asarray(camera["camera_matrix"], float)
    kt = hidden.camera.camera_matrix
    return {
        "fx": float(k[0, 0] / kt[0, 0] - 1.0),
        "fy": float(k[1, 1] / kt[1, 1] - 1.0),
        "cx_px": float(k[0, 2] - kt[0, 2]),
        "cy_px": float(k[1, 2] - kt[1, 2]),
        "centre_px": float(np.hypot(k[0, 2] - kt[0, 2], k[1, 2] - kt[1, 2])),
    }


def arena_error_mm(hidden: HiddenRig, arena: dict, radius_m: float = 0.18, n: int = 15) -> float:
    """An arena.json's ``data`` against the hidden camera: floor points on a grid inside
    ``radius_m`` of the centre are projected by the hidden camera (raw pixels, its lens), mapped
    back to the floor by the calibration; the largest distance from where they are, mm."""
    from vision.rectify import ArenaModel, pixels_to_arena

    g = np.linspace(-radius_m, radius_m, n)
    xy = np.array([(x, y) for x in g for y in g if x * x + y * y <= radius_m**2])
    pixels = hidden.camera.project(np.column_stack([xy, np.zeros(len(xy))]))
    back = pixels_to_arena(ArenaModel.from_dict(arena), pixels)
    return float(np.linalg.norm(back - xy, axis=1).max() * 1000.0)
