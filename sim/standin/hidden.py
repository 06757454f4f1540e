"""The served rig's hidden parameters: how a user's rig differs from the nominal twin, drawn
from a seed within realistic ranges (``draw_hidden``), or the nominal twin itself
(``nominal_rig``, what a plain ``ergo twin serve`` serves).

Every range below says where it comes from (a datasheet, a configuration, or "guess");
docs/standin.md has the table. What is hidden:

- per joint, the servo's direction (+1/-1) and offset: ``servo_angle = direction *
  joint_angle + offset`` (rad; ``robot.angles``, the convention of ``robot.dynamixel.arm`` and
  ``calibration/joints.py``), applied to the bus emulators' raw positions: Dynamixel steps
  ``512 + servo_angle / step``, CANopen counts ``servo_angle * counts_per_rev / 2 pi``. The
  CANopen drives' zero marks are the same offsets unless drawn ``zero_marks="anywhere"``: then
  each drive's encoder reads its joint's zero mark anywhere on the turn, past pi included, and
  up to two turns either way (a multi-turn encoder counts on from wherever it was zeroed; a
  drive's encoder is not a horn put on by eye);
- the overhead camera: its pose (height, tilt, roll about its axis, offset) and its lens (focal
  lengths, principal point, k1 k2 p1 p2), applied to the served frames;
- the servos' dynamics (``sim.servo_model.ServoModel``: kp, damping, armature, friction loss,
  command delay);
- where the ball starts on its ring.

This module draws and writes them; only ``testkit.standin_truth`` reads the file back, and only
tests and bench scripts import that (tests/sim/standin/test_secrecy.py checks it).

Units: metres, radians, seconds, pixels.
"""

from __future__ import annotations

import json
import math
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from plumbing.files import atomic_write
from robot.angles import TURN
from robot.spec import ERGO_JR_JOINTS
from sim.models.make_scene import (
    ARENA_MARKER_SIZE,
    ARENA_MARKERS,
    BALL_START,
    CAMERA_FOVY,
    CAMERA_HEIGHT,
    OUTER_RADIUS,
    WALL_HEIGHT,
)
from sim.servo_model import NOMINAL, ServoModel

N_JOINTS = len(ERGO_JR_JOINTS)

# ---- the servos' mounting -----------------------------------------------------------------
# A horn pressed on by eye, printed parts with play: the servo's zero lies a few degrees off
# the joint's (guess). Poppy's assembly guide warns that the dot on the horn must meet the dot
# on the servo's axis, or the structure's zero no longer matches the servo's: a horn put on one
# spline tooth off is the classic mistake. The XL-320's tooth count is not in its datasheet:
# 15 degrees (an RC servo's 24-25 teeth) is a guess.
ASSEMBLY_ERROR_DEG = 5.0  # offsets uniform in +-5 deg ...
TOOTH_DEG = 15.0  # ... plus, with probability TOOTH_PROBABILITY, one tooth either way
TOOTH_PROBABILITY = 0.3  # per joint (guess: about one joint in three on a first assembly)
# With zero_marks="anywhere", a CANopen drive's zero mark: uniform on the turn, plus a whole
# number of turns uniform in -ZERO_MARK_TURNS..ZERO_MARK_TURNS (guess: a multi-turn encoder
# zeroed at the factory reads any count; a single-turn one reads 0..2 pi).
ZERO_MARKS = ("horn", "anywhere")
ZERO_MARK_TURNS = 2
# Directions: the original Poppy Ergo Jr configuration mounts m1 and m4 "direct" and m2, m3,
# m5, m6 "indirect"; a stand-in draws each joint's +1/-1 at even odds, so that software which
# assumed one pattern would be caught.

# ---- the overhead camera ------------------------------------------------------------------
# The Poppy Ergo Jr's configured camera resolution (its configuration: 640 x 480) and the
# Raspberry Pi Camera Module v2's 48.8 degree vertical field of view (Raspberry Pi camera
# documentation): fy = 240 / tan(24.4 deg) = 530 px.
CAMERA_SIZE = (640, 480)  # (width, height), pixels
NOMINAL_FOCAL_PX = (CAMERA_SIZE[1] / 2) / math.tan(math.radians(48.8 / 2))
FOCAL_SPREAD = 0.10  # focal length uniform within +-10 % (guess: other lenses and modules)
ASPECT_SPREAD = 0.005  # fx / fy within +-0.5 % (guess: pixels are nearly square)
PRINCIPAL_SPREAD_PX = 15.0  # principal point within +-15 px of the centre (guess)
# Lens distortion (OpenCV's model, k3 = 0): cheap wide lenses are barrel-distorted (k1 < 0);
# guesses spanning mild pincushion to strong barrel.
K1_RANGE = (-0.30, 0.05)
K2_RANGE = (-0.05, 0.15)
TANGENTIAL_MAX = 0.002  # p1, p2 within +-0.002 (a lens slightly off-centre; guess)
# Pose: clamped by hand above the arena at about the guide's height.
HEIGHT_RANGE_M = (0.50, 0.60)  # guess: 0.55 m +- 5 cm
MAX_TILT_DEG = 3.0  # optical axis off the vertical by up to 3 deg, any azimuth (guess)
MAX_ROLL_DEG = 5.0  # image axes turned about the optical axis by up to +-5 deg (guess)
MAX_SHIFT_M = 0.02  # camera within +-2 cm of the arm's base in x and y (guess)
# A drawn camera must show the arena: the markers (with their white quiet zone) and the wall
# at least this far inside the frame, else the draw is repeated (a person moves the camera).
VIEW_MARGIN_PX = 8.0
MAX_DRAWS = 200

# ---- the servos' dynamics -----------------------------------------------------------------
# Each fitted quantity: one factor for the rig, log-uniform in [1/2, 2] x nominal (an unknown
# servo batch, supply voltage, load), times a per-joint factor log-uniform in [1/1.15, 1.15]
# (unit-to-unit spread). Both guesses, large enough that a fit must find them.
RIG_FACTOR = 2.0
JOINT_FACTOR = 1.15
# Friction loss: the nominal 0.001 N.m is a numerical guess; a 238:1 plastic gearbox resists
# being back-driven far more. Log-uniform between 0.0005 and 0.02 N.m (up to 5 % of the
# XL-320's 0.39 N.m stall torque; guess).
FRICTIONLOSS_RANGE = (0.0005, 0.02)
# Command delay: a USB-serial adapter's latency timer (FTDI's default 16 ms) plus the servo's
# own processing: uniform 5-30 ms (guess within those bounds).
DELAY_RANGE_S = (0.005, 0.030)

# ---- the ball -----------------------------------------------------------------------------
BALL_RING_M = (0.13, 0.17)  # its centre lives on this band (docs/twin.md)

# Where the hidden file goes unless told (one per seed, overwritten: the same seed gives the
# same content).
HIDDEN_SUFFIX = "-hidden.json"


class StandinError(ValueError):
    """Bad stand-in input (seed, file); the message is one line."""


@dataclass(frozen=True)
class HiddenCamera:
    """The overhead camera as it is (what a camera calibration should recover).

    Attributes:
        size: (width, height) of the frames, pixels.
        camera_matrix: shape (3, 3), pixels (OpenCV; pixel centres at integers).
        dist_coeffs: (k1, k2, p1, p2), shape (4,).
        position: the camera's optical centre in the world, shape (3,), metres.
        rotation: world-to-camera rotation, shape (3, 3), in OpenCV's camera frame (x right,
            y down, z along the optical axis): a world point X is at ``rotation @ (X -
            position)`` in the camera frame.
    """

    size: tuple[int, int]
    camera_matrix: np.ndarray
    dist_coeffs: np.ndarray
    position: np.ndarray
    rotation: np.ndarray

    @property
    def translation(self) -> np.ndarray:
        """OpenCV's ``tvec``: ``-rotation @ position``, shape (3,), metres."""
        return -self.rotation @ self.position

    def mujoco_quat(self) -> np.ndarray:
        """The MJCF camera's orientation (it looks along its -z with y up), shape (4,) w x y z."""
        import mujoco

        frame = (np.diag([1.0, -1.0, -1.0]) @ self.rotation).T  # columns: camera axes in world
        quat = np.zeros(4)
        mujoco.mju_mat2Quat(quat, np.ascontiguousarray(frame).reshape(-1))
        return quat

    def project(self, points: np.ndarray) -> np.ndarray:
        """Pixels of world points, shape (N, 3) metres -> (N, 2) pixels (u, v)."""
        import cv2

        rvec, _ = cv2.Rodrigues(self.rotation)
        px, _ = cv2.projectPoints(
            np.asarray(points, np.float64).reshape(-1, 1, 3),
            rvec,
            self.translation,
            self.camera_matrix,
            self.dist_coeffs,
        )
        return px.reshape(-1, 2)

    def to_dict(self) -> dict[str, Any]:
        return {
            "size": list(self.size),
            "camera_matrix": self.camera_matrix.tolist(),
            "dist_coeffs": self.dist_coeffs.tolist(),
            "position": self.position.tolist(),
            "rotation": self.rotation.tolist(),
            "tvec": self.translation.tolist(),
        }


@dataclass(frozen=True)
class HiddenRig:
    """Everything that differs between a served rig and what the software assumes.

    Attributes:
        seed: the stand-in's seed, or None for the nominal twin.
        directions: +1/-1 per joint, shape (6,).
        offsets: servo angle at joint zero per joint, shape (6,), rad.
        camera: the overhead camera.
        servos: the servos' dynamics.
        ball_xy: where the ball starts, (x, y) metres.
        can_zero_marks: the CANopen drives' angle at each joint's zero mark (counts x 2 pi /
            counts per revolution), shape (6,), rad, any number of turns; None: ``offsets``.
    """

    seed: int | None
    directions: np.ndarray
    offsets: np.ndarray
    camera: HiddenCamera
    servos: ServoModel
    ball_xy: tuple[float, float]
    can_zero_marks: np.ndarray | None = None

    @property
    def can_offsets(self) -> np.ndarray:
        """The CANopen drives' offsets (``robot.angles``: drive angle at joint zero), shape
        (6,), rad: ``can_zero_marks``, else the servos' ``offsets``."""
        marks = self.offsets if self.can_zero_marks is None else self.can_zero_marks
        return np.asarray(marks, float).copy()

    def to_dict(self) -> dict[str, Any]:
        from robot.dynamixel.control_table import XL320

        cpr = canopen_counts_per_rev()
        return {
            "what": (
                "the stand-in rig's hidden parameters (sim/standin/hidden.py): for tests and "
                "bench scripts only, never read by a calibration"
            ),
            "seed": self.seed,
            "joints": {
                "names": list(ERGO_JR_JOINTS),
                "convention": "servo_angle = direction * joint_angle + offset (rad)",
                "directions": [int(d) for d in self.directions],
                "offsets_rad": self.offsets.tolist(),
                "offsets_deg": np.degrees(self.offsets).tolist(),
                "dynamixel_steps_at_zero": (
                    XL320.position_centre + self.offsets / XL320.rad_per_step
                ).tolist(),
                "canopen_zero_marks_rad": self.can_offsets.tolist(),
                "canopen_counts_at_zero": (self.can_offsets * cpr / math.tau).tolist(),
                "canopen_counts_per_rev": cpr,
            },
            "camera": self.camera.to_dict(),
            "servos": self.servos.to_dict(),
            "ball_xy": list(self.ball_xy),
            "markers": {
                "markers": {str(k): list(v) for k, v in ARENA_MARKERS.items()},
                "size_m": ARENA_MARKER_SIZE,
            },
        }


def canopen_counts_per_rev() -> float:
    """Increments per revolution of the emulated drives (0x608F of their EDS)."""
    return 65536.0  # robot/canopen/ergo_drive.eds, 0x608F sub 1 / sub 2 = 65536 / 1


def rotation_matrix(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rotation about a unit ``axis`` (3,) by ``angle`` rad, shape (3, 3) (Rodrigues)."""
    import cv2

    r, _ = cv2.Rodrigues(np.asarray(axis, np.float64).reshape(3) * angle)
    return r


def camera_rotation(tilt: float, azimuth: float, roll: float) -> np.ndarray:
    """World-to-camera rotation (OpenCV frame) of a camera looking down, its optical axis
    tilted by ``tilt`` rad about the horizontal axis at ``azimuth`` rad, its image turned by
    ``roll`` rad about the optical axis; (0, 0, 0): image right = +x, image up = +y."""
    mj = rotation_matrix(np.array([math.cos(azimuth), math.sin(azimuth), 0.0]), tilt)
    mj = mj @ rotation_matrix(np.array([0.0, 0.0, 1.0]), roll)  # MuJoCo camera axes in world
    return np.diag([1.0, -1.0, -1.0]) @ mj.T


def nominal_camera(size: tuple[int, int] = (240, 240)) -> HiddenCamera:
    """The committed scene's overhead camera (``make_scene.py``): ideal, straight down at
    ``CAMERA_HEIGHT``, ``CAMERA_FOVY``; ``size`` (width, height)."""
    w, h = size
    f = (h / 2.0) / math.tan(math.radians(CAMERA_FOVY) / 2.0)
    k = np.array([[f, 0.0, (w - 1) / 2.0], [0.0, f, (h - 1) / 2.0], [0.0, 0.0, 1.0]])
    return HiddenCamera(
        (w, h), k, np.zeros(4), np.array([0.0, 0.0, CAMERA_HEIGHT]), camera_rotation(0, 0, 0)
    )


def nominal_rig() -> HiddenRig:
    """The twin as the software assumes it: what a plain ``ergo twin serve`` serves."""
    return HiddenRig(
        None, np.ones(N_JOINTS), np.zeros(N_JOINTS), nominal_camera(), NOMINAL, BALL_START
    )


def arena_points() -> np.ndarray:
    """World points a camera must show: the markers' quiet-zone corners and the wall's top
    rim, shape (N, 3), metres."""
    pts = []
    half = ARENA_MARKER_SIZE / 2 + ARENA_MARKER_SIZE / 6  # a cell of quiet zone (4x4 + border)
    for x, y in ARENA_MARKERS.values():
        for sx, sy in ((-1, -1), (-1, 1), (1, 1), (1, -1)):
            pts.append((x + sx * half, y + sy * half, 0.0))
    rim = OUTER_RADIUS + 0.01  # the wall's outer face (make_scene.py: 1 cm thick)
    for a in np.linspace(0, 2 * np.pi, 36, endpoint=False):
        pts.append((rim * math.cos(a), rim * math.sin(a), WALL_HEIGHT))
    return np.array(pts)


def _in_view(camera: HiddenCamera) -> bool:
    px = camera.project(arena_points())
    w, h = camera.size
    m = VIEW_MARGIN_PX
    return bool(
        np.all(
            (px[:, 0] >= m) & (px[:, 0] <= w - 1 - m) & (px[:, 1] >= m) & (px[:, 1] <= h - 1 - m)
        )
    )


def _monotonic(camera: HiddenCamera) -> bool:
    """The lens maps radii one-to-one out to the frame's corners (no fold-over)."""
    k = camera.camera_matrix
    w, h = camera.size
    k1, k2 = camera.dist_coeffs[:2]
    r_max = math.hypot(
        max(k[0, 2], w - 1 - k[0, 2]) / k[0, 0], max(k[1, 2], h - 1 - k[1, 2]) / k[1, 1]
    )
    r = np.linspace(0.0, 1.5 * r_max, 200)
    return bool(np.all(1 + 3 * k1 * r**2 + 5 * k2 * r**4 > 0.2))


def _log_uniform(rng: np.random.Generator, lo: float, hi: float, size: int | None = None):
    return np.exp(rng.uniform(math.log(lo), math.log(hi), size))


def _draw_camera(rng: np.random.Generator) -> HiddenCamera:
    w, h = CAMERA_SIZE
    f = NOMINAL_FOCAL_PX * rng.uniform(1 - FOCAL_SPREAD, 1 + FOCAL_SPREAD)
    fx = f * rng.uniform(1 - ASPECT_SPREAD, 1 + ASPECT_SPREAD)
    cx = (w - 1) / 2 + rng.uniform(-PRINCIPAL_SPREAD_PX, PRINCIPAL_SPREAD_PX)
    cy = (h - 1) / 2 + rng.uniform(-PRINCIPAL_SPREAD_PX, PRINCIPAL_SPREAD_PX)
    dist = np.array(
        [
            rng.uniform(*K1_RANGE),
            rng.uniform(*K2_RANGE),
            rng.uniform(-TANGENTIAL_MAX, TANGENTIAL_MAX),
            rng.uniform(-TANGENTIAL_MAX, TANGENTIAL_MAX),
        ]
    )
    height = rng.uniform(*HEIGHT_RANGE_M)
    shift = rng.uniform(-MAX_SHIFT_M, MAX_SHIFT_M, 2)
    tilt = math.radians(rng.uniform(0.0, MAX_TILT_DEG))
    azimuth = rng.uniform(0.0, 2 * math.pi)
    roll = math.radians(rng.uniform(-MAX_ROLL_DEG, MAX_ROLL_DEG))
    k = np.array([[fx, 0.0, cx], [0.0, f, cy], [0.0, 0.0, 1.0]])
    position = np.array([shift[0], shift[1], height])
    return HiddenCamera((w, h), k, dist, position, camera_rotation(tilt, azimuth, roll))


def _draw_servos(rng: np.random.Generator) -> ServoModel:
    def scaled(name: str) -> tuple[float, ...]:
        rig = _log_uniform(rng, 1 / RIG_FACTOR, RIG_FACTOR)
        joints = _log_uniform(rng, 1 / JOINT_FACTOR, JOINT_FACTOR, N_JOINTS)
        return tuple(NOMINAL.array(name) * rig * joints)

    kp, damping, armature = scaled("kp"), scaled("damping"), scaled("armature")
    friction = _log_uniform(rng, *FRICTIONLOSS_RANGE) * _log_uniform(
        rng, 1 / JOINT_FACTOR, JOINT_FACTOR, N_JOINTS
    )
    return NOMINAL.replace(
        kp=kp,
        damping=damping,
        armature=armature,
        frictionloss=tuple(friction),
        delay_s=float(rng.uniform(*DELAY_RANGE_S)),
    )


def draw_hidden(seed: int, zero_marks: str = "horn") -> HiddenRig:
    """A stand-in rig's hidden parameters, a pure function of ``seed`` (an int >= 0) and
    ``zero_marks``: ``"horn"``, the CANopen drives' zero marks are the servos' offsets (a few
    degrees); ``"anywhere"``, drawn on the whole turn and beyond (``ZERO_MARK_TURNS``). The
    other draws are the same either way.

    Raises:
        StandinError: a negative or non-integer seed, an unknown ``zero_marks``.
    """
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise StandinError(f"--stand-in seed must be an integer >= 0, got {seed!r}")
    if zero_marks not in ZERO_MARKS:
        raise StandinError(
            f"--zero-marks must be one of {', '.join(ZERO_MARKS)}, got {zero_marks!r}"
        )
    rng = np.random.default_rng([int(seed), 0x57A1D])  # the stand-in's own stream
    directions = rng.choice([-1.0, 1.0], N_JOINTS)
    offsets = np.radians(rng.uniform(-ASSEMBLY_ERROR_DEG, ASSEMBLY_ERROR_DEG, N_JOINTS))
    teeth = rng.choice(
        [-1, 0, 1],
        N_JOINTS,
        p=[TOOTH_PROBABILITY / 2, 1 - TOOTH_PROBABILITY, TOOTH_PROBABILITY / 2],
    )
    offsets = offsets + np.radians(TOOTH_DEG) * teeth
    for _ in range(MAX_DRAWS):
        camera = _draw_camera(rng)
        if _monotonic(camera) and _in_view(camera):
            break
    else:  # pragma: no cover - the ranges leave most draws in view (measured: docs/standin.md)
        raise StandinError(f"stand-in seed {seed}: no camera in {MAX_DRAWS} draws shows the arena")
    servos = _draw_servos(rng)
    angle = rng.uniform(0.0, 2 * math.pi)
    radius = rng.uniform(*BALL_RING_M)
    ball = (radius * math.cos(angle), radius * math.sin(angle))
    marks = None
    if zero_marks == "anywhere":  # drawn last: the draws above stay those of "horn"
        turns = rng.integers(-ZERO_MARK_TURNS, ZERO_MARK_TURNS + 1, N_JOINTS)
        marks = rng.uniform(0.0, TURN, N_JOINTS) + TURN * turns
    return HiddenRig(int(seed), directions, offsets, camera, servos, ball, marks)


def default_hidden_path(seed: int) -> Path:
    """Where ``ergo twin serve --stand-in SEED`` writes the hidden file unless told."""
    return Path(tempfile.gettempdir()) / f"ergo-standin-{seed}{HIDDEN_SUFFIX}"


def write_hidden(rig: HiddenRig, path: str | os.PathLike[str]) -> Path:
    """Write the hidden parameters as JSON (atomically: a reader never sees half a file)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    return atomic_write(path, json.dumps(rig.to_dict(), indent=2) + "\n")
