"""Reads a stand-in rig's hidden parameters back (the file ``ergo twin serve --stand-in SEED``
writes): the truth that tests and bench scripts compare a calibration against.

Nothing but tests/ and bench/ may import this module (tests/sim/standin/test_secrecy.py reads
every import of the project's source to check it): a calibration that read the truth would
prove nothing.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

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
        )
    except OSError as exc:
        raise StandinError(f"cannot read the hidden parameters {path}: {exc}") from None
    except (ValueError, KeyError, TypeError, IndexError, ServoModelError) as exc:
        raise StandinError(f"{path} is not a stand-in's hidden file: {exc!r}") from None
