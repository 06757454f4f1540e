"""The names LeRobot sees of the Ergo Jr, the same for the three robots, the leader, the
scripted teleoperator and the environment, and the same as ``ergo export lerobot``'s dataset:

- one float per joint, ``m1.pos`` .. ``m6.pos`` (the export's ``JOINT_FEATURES``: the joints of
  ``robot.spec.ERGO_JR_JOINTS``, named as LeRobot names an arm's joint positions), rad: the
  joints read (observation) and the goal positions (action); LeRobot gathers them into
  ``observation.state`` and ``action``, each named ``[m1.pos, ..., m6.pos]``;
- ``overhead``: the centre square of the overhead camera, (side, side, 3) RGB uint8, which
  LeRobot records as ``observation.images.overhead`` (the export's ``VIDEO_KEY``);
- the robot type ``poppy_ergo_jr`` (the export's ``ROBOT_TYPE``), written as a dataset's
  ``robot_type``.

A dataset recorded on one robot trains a policy that runs on the others and on the
environment, and an exported exploration trains one too.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from explore.export.lerobot import JOINT_FEATURES, ROBOT_TYPE, VIDEO_KEY
from vision.observation import OBSERVATION_SIZE, square_observation

JOINTS: tuple[str, ...] = JOINT_FEATURES
IMAGES_PREFIX = "observation.images."
IMAGE_KEY = VIDEO_KEY.removeprefix(IMAGES_PREFIX)  # "overhead"
STATE_KEY = "observation.state"
ACTION_KEY = "action"
# The overhead frame's side by default, pixels: the learner's 64 px observation and the twin's
# Gymnasium environment's image (vision/observation.py), so that the three agree by default.
IMAGE_SIDE = OBSERVATION_SIZE
__all__ = [
    "ACTION_KEY",
    "IMAGE_KEY",
    "IMAGE_SIDE",
    "JOINTS",
    "ROBOT_TYPE",
    "STATE_KEY",
    "action_features",
    "joints_dict",
    "joints_vector",
    "observation_features",
    "rgb_square",
]


def action_features() -> dict[str, type]:
    """The action: one float per joint, its goal position, rad."""
    return dict.fromkeys(JOINTS, float)


def observation_features(image_side: int | None) -> dict[str, type | tuple[int, int, int]]:
    """The observation: one float per joint, its position, rad; and the overhead frame's shape
    (side, side, 3) unless ``image_side`` is None (no camera)."""
    out: dict[str, type | tuple[int, int, int]] = dict.fromkeys(JOINTS, float)
    if image_side is not None:
        out[IMAGE_KEY] = (image_side, image_side, 3)
    return out


def joints_vector(values: Mapping[str, object], what: str = "action") -> np.ndarray:
    """``{m1.pos: rad, ..., m6.pos: rad}`` -> shape (6,) rad, in joint order; a one-line
    ``ValueError`` naming a missing joint or a value that is not a number."""
    missing = [j for j in JOINTS if j not in values]
    if missing:
        raise ValueError(
            f"{what} lacks joint(s) {', '.join(missing)}: an Ergo Jr {what} names "
            f"{', '.join(JOINTS)}"
        )
    out = np.empty(len(JOINTS))
    for i, j in enumerate(JOINTS):
        try:
            out[i] = float(values[j])  # type: ignore[arg-type]
        except (TypeError, ValueError):
            raise ValueError(f"{what} {j} is not a number: {values[j]!r}") from None
    return out


def joints_dict(vector: np.ndarray) -> dict[str, float]:
    """Shape (6,) rad -> ``{m1.pos: rad, ..., m6.pos: rad}`` (Python floats)."""
    return {j: float(v) for j, v in zip(JOINTS, np.asarray(vector).reshape(-1), strict=True)}


def rgb_square(frame_bgr: np.ndarray, side: int) -> np.ndarray:
    """The centre square of a BGR frame at (side, side), as RGB uint8 (what LeRobot records):
    the same square as the 64 px observation and the export's frames."""
    return np.ascontiguousarray(square_observation(frame_bgr, side)[..., ::-1])
