"""What the physical rigs (``dynamixel``, ``canopen``) share: their rig id, the camera options
and the camera they name, the joint calibration they read (offsets, directions and the
calibrated limits their arm clamps to), the calibration files they use, and their scene (the
arena as built, the twin's dimensions).

A physical rig is named by its own id (``--rig-id``): the folder its calibration files are
kept under. The default id ``twin`` belongs to the simulated twin and is refused for a
physical rig (``check_rig_id``), so that a forgotten ``--rig-id`` is one line, not a run on
no calibration.

Joint calibration (``joint_setup``): the rig reads ``joints.json`` of its id (or the file the
option ``joint_calibration`` names) and builds its arm with the file's offsets and directions
and the spec narrowed to the file's limits (the tighter of the two, ``ArmSpec.with_limits``),
which the arm's clamp then holds every command to. No file: one warning, servo zero taken as
joint zero, the spec's limits. A damaged or foreign file: refused in one line naming it.
Hand-typed ``offsets`` / ``directions`` options are refused when they differ from the file;
``joint_calibration=none`` says that the options win (no file read, the spec's limits).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from explore.learner.scene import Scene
from explore.options import BadOption
from explore.rigs.arena import TWIN_ARENA
from explore.rigs.rig import NO_JOINT_CALIBRATION, RigConfig, RigError
from explore.rigs.video import VideoOptions
from robot.angles import wrap
from robot.spec import ArmSpec, ergo_jr_spec
from robot.torque_guardian import ON_DEATH
from vision.camera import Camera, CameraError
from vision.make_camera import make_camera

log = logging.getLogger(__name__)
CAMERA = "a device index, video path or URL"
TWIN_RIG_ID = RigConfig.rig_id  # the default id, the simulated twin's
# Hand-typed offsets within this of the file's, modulo whole turns, are the same offsets (rad):
# far below an XL-320's position unit (0.005 rad), far above JSON round-off.
SAME_OFFSET_RAD = 1e-6


@dataclass(frozen=True)
class HardwareOptions(VideoOptions):
    """Options every physical rig takes (and ``record_video``: ``explore.rigs.video``).

    Attributes:
        camera: device index (``0``), video path or URL (``http://127.0.0.1:PORT/stream.mjpg``
            from ``ergo twin serve``); default 0. A video is played at its own rate, like a
            live camera.
        camera_width, camera_height, camera_fps: requested camera mode (optional).
        arena_calibration: the arena calibration file (default: the rig's, found by its id).
        joint_calibration: the joint calibration file (default: the rig's ``joints.json``,
            found by its id), or ``"none"``: read none, use ``directions`` / ``offsets`` and
            the spec's limits.
        directions, offsets: per joint +1/-1 and rad, in the rig's own convention (default:
            the joint calibration's, else +1 and 0); refused when they differ from the joint
            calibration file's unless ``joint_calibration`` is ``"none"``.
        on_crash: what the servos do when the controller's process dies without its own
            torque-off (SIGKILL, an OOM kill): ``"limp"`` (default: torque off, by a guardian
            process and, on CANopen, the drives' heartbeat consumer) or ``"hold"`` (they keep
            their last target; docs/real_arm.md).
    """

    camera: int | str = field(default=0, metadata={"expected": CAMERA})
    camera_width: int | None = None
    camera_height: int | None = None
    camera_fps: float | None = None
    arena_calibration: str | None = None
    joint_calibration: str | None = None
    directions: tuple[float, ...] | None = None
    offsets: tuple[float, ...] | None = None
    on_crash: str = "limp"

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.on_crash not in ON_DEATH:
            raise BadOption(
                "on_crash", f"must be one of {', '.join(ON_DEATH)}, got {self.on_crash!r}"
            )
        if isinstance(self.camera, int) and self.camera < 0:
            raise BadOption("camera", f"must be {CAMERA}, got {self.camera!r}")


def rig_camera(options: HardwareOptions, rig: str) -> Camera:
    """The camera of a physical rig (unconnected); a ``RigError`` for a source it cannot be."""
    try:
        return make_camera(
            options.camera, options.camera_width, options.camera_height, options.camera_fps,
            files="live",
        )  # fmt: skip
    except CameraError as exc:
        raise RigError(f"rig {rig!r}: {exc}") from exc


def per_joint(options: HardwareOptions, key: str, n: int, rig: str) -> tuple[float, ...] | None:
    """``options.<key>`` (directions or offsets) checked to hold ``n`` values, or None."""
    value: Any = getattr(options, key)
    if value is not None and len(value) != n:
        raise RigError(f"rig {rig!r}: option {key} needs {n} values, got {list(value)}")
    return value


def check_rig_id(config: RigConfig) -> None:
    """A physical rig needs its own id (``TWIN_RIG_ID`` is the twin's): a ``RigError`` naming
    ``--rig-id``, or one naming what is wrong with the id."""
    from calibration.store import CalibrationError
    from calibration.store import check_rig_id as valid_id

    if config.rig_id == TWIN_RIG_ID:
        raise RigError(
            f"rig {config.name!r} needs its own id: give --rig-id ID, the name its calibration "
            f"files are kept under (ergo calibrate joints|camera|arena --rig-id ID); "
            f"{TWIN_RIG_ID!r} is the simulated twin's"
        )
    try:
        valid_id(config.rig_id)
    except CalibrationError as exc:
        raise RigError(f"rig {config.name!r}: {exc}") from None


@dataclass(frozen=True)
class JointSetup:
    """How a physical rig's arm is built from its joint calibration.

    Attributes:
        spec: the Ergo Jr's spec, its limits narrowed to the calibration's.
        directions: +1/-1 per joint, or None (the arm's default, +1).
        offsets: per joint, rad, in the rig's convention, or None (the arm's default, 0).
        path: the calibration file read, or None.
    """

    spec: ArmSpec
    directions: tuple[float, ...] | None
    offsets: tuple[float, ...] | None
    path: Path | None


def joint_calibration_path(config: RigConfig) -> Path | None:
    """The joint calibration file a physical rig reads (it may not exist), or None when the
    option ``joint_calibration`` is ``"none"`` (``RigConfig.resolved``)."""
    return config.resolved().calibration.joints


def joint_setup(
    config: RigConfig,
    options: HardwareOptions,
    to_rig_offsets: Callable[[np.ndarray, np.ndarray], np.ndarray] = lambda d, o: o,
) -> JointSetup:
    """The spec, directions and offsets of a physical rig's arm (see the module docstring).

    Args:
        config: the rig (its id finds ``joints.json``).
        options: its options (``joint_calibration``, ``directions``, ``offsets``).
        to_rig_offsets: (directions, calibration offsets: servo angle at joint zero, rad) ->
            the offsets in the rig's own convention (the identity for ``DynamixelArm``).

    Raises:
        RigError: one line: a damaged or foreign file (naming it), options of the wrong length,
            or options that differ from the file's.
    """
    from calibration.joints import load_joints_file
    from calibration.store import CalibrationError, CalibrationMissing

    spec = ergo_jr_spec()
    n = spec.n
    directions = per_joint(options, "directions", n, config.name)
    offsets = per_joint(options, "offsets", n, config.name)
    path = joint_calibration_path(config)
    if path is None:
        return JointSetup(spec, directions, offsets, None)
    try:
        cal = load_joints_file(path, spec)
    except CalibrationMissing:
        log.warning(
            "no joint calibration for rig %r (no file %s): servo zero is taken as joint zero, "
            "the spec's limits hold; run 'ergo calibrate joints --rig-id %s ...' (or give "
            "--rig-option joint_calibration=none to say so)",
            config.rig_id, path, config.rig_id,
        )  # fmt: skip
        return JointSetup(spec, directions, offsets, None)
    except CalibrationError as exc:
        raise RigError(f"{exc} (a damaged or foreign joint calibration is not ignored)") from None
    file_dirs = tuple(float(d) for d in cal.directions)
    file_offsets = tuple(float(o) for o in to_rig_offsets(cal.directions, cal.offsets))
    for key, given, held in (
        ("directions", directions, file_dirs),
        ("offsets", offsets, file_offsets),
    ):
        # offsets a whole turn apart are the same zero mark (robot.angles: the one rule)
        apart = np.subtract(given, held) if given is not None else None
        if key == "offsets" and apart is not None:
            apart = wrap(apart)
        if apart is not None and not np.all(np.abs(apart) <= SAME_OFFSET_RAD):
            raise RigError(
                f"rig option {key} {list(given)} differs from {path} "
                f"({[round(v, 4) for v in held]}): drop the option to use the file, or give "
                f"--rig-option joint_calibration={NO_JOINT_CALIBRATION} to use the options "
                "(and the spec's limits) instead"
            )
    return JointSetup(cal.apply_to(spec), file_dirs, file_offsets, path)


def calibration_files(config: RigConfig) -> list[tuple[str, Path]]:
    """(kind, path) of the calibration files a physical rig reads that exist: its joint
    calibration, the camera calibration beside its arena calibration (which the arena file is
    checked against) and its arena calibration; for the ``sim`` rig its fitted servos
    (``dynamics.json``), if any; none for other rigs with nothing physical attached. The files
    are the config's (``RigConfig.resolved``)."""
    from explore.rigs.rig import is_physical

    if is_physical(config.name):
        return config.resolved().calibration.existing(("joints", "camera", "arena"))
    if config.name == "sim":  # the twin reads its rig id's fitted servos, if any
        return config.resolved().calibration.existing(("dynamics",))
    return []


def scene(config: Any, options: Any) -> Scene:
    """A physical rig's scene: the Ergo Jr arena as built (sim/models/make_scene.py)."""
    return TWIN_ARENA
