"""Calibration files: one versioned JSON file per kind (camera, arena, joints, dynamics) per
rig id (dynamics: the twin's servos fitted to the rig's arm, ``calibration.dynamics``).

Where they live (``<root>/<rig_id>/<kind>.json``) and their envelope (schema, kind, version,
rig id) are ``robot/calibration_files.py``'s, re-exported here; a dynamics payload's checks are
``sim/servo_model.py``'s (``check_dynamics``: the served twin reads it too). Payloads are
validated before they are written (a bad one never replaces a good file) and after they are
read; a validation error is one line that names the file and the bad field. Writes are
atomic: a temporary file in the same folder, fsync, then ``os.replace``.
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Callable
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from calibration.camera import check_camera_payload
from plumbing.fields import Fields, is_matrix
from plumbing.files import atomic_write
from robot.calibration_files import (
    DEFAULT_DIR,
    ENV_DIR,
    KINDS,
    SCHEMA,
    VERSIONS,
    CalibrationError,
    CalibrationMissing,
    calibration_path,
    calibration_root,
    check_rig_id,
    read_document,
)

__all__ = [
    "DEFAULT_DIR",
    "ENV_DIR",
    "KINDS",
    "SCHEMA",
    "VERSIONS",
    "CalibrationError",
    "CalibrationMissing",
    "calibration_path",
    "calibration_root",
    "check_rig_id",
    "file_sha256",
    "load",
    "load_arena_file",
    "load_document",
    "load_file",
    "save",
    "validate",
]


# ---- validation --------------------------------------------------------------------------
# Bounds of an arena file's numbers that no real calibration comes near (guesses, far out):
# a pixel -> metre homography normalised to h[2][2] = 1 has entries of about 1e-3 (metres per
# pixel) to 1; its condition number is about 1e3 for a camera looking down at a 0.5 m arena
# from 0.5-1 m (singular values ~1 and ~1e-3). Distortion coefficients of real lenses stay
# within tens (OpenCV's rational model included); focal lengths within 1e5 px.
ARENA_HOMOGRAPHY_MAX_ABS = 1e6
ARENA_HOMOGRAPHY_MAX_COND = 1e12
ARENA_DISTORTION_MAX_ABS = 1e3
ARENA_FOCAL_MAX_PX = 1e6


def _check_arena_numbers(c: Fields) -> None:
    """What finite is not enough for: a homography that is singular or out of all scale, a
    distortion or focal length no lens has (1e300 passed the finite checks and broke every
    pixel mapped through it)."""
    import numpy as np

    h = np.asarray(c.data["homography"], dtype=float)
    if np.abs(h).max() > ARENA_HOMOGRAPHY_MAX_ABS:
        c.fail("homography", f"has an entry of {np.abs(h).max():g}: out of all scale (damaged?)")
    with np.errstate(all="ignore"):
        cond = float(np.linalg.cond(h))
    if not cond < ARENA_HOMOGRAPHY_MAX_COND:
        c.fail("homography", f"is singular (condition number {cond:g}): it maps no plane")
    dist = np.asarray(c.data["dist_coeffs"], dtype=float)
    if np.abs(dist).max() > ARENA_DISTORTION_MAX_ABS:
        c.fail(
            "dist_coeffs",
            f"has a coefficient of {np.abs(dist).max():g}: no lens distorts that much (damaged?)",
        )
    k = c.data["camera_matrix"]
    if not (0 < k[0][0] <= ARENA_FOCAL_MAX_PX and 0 < k[1][1] <= ARENA_FOCAL_MAX_PX):
        c.fail("camera_matrix", f"focal lengths must be in (0, {ARENA_FOCAL_MAX_PX:g}] px")


def _validate_arena(c: Fields) -> None:
    _validate_camera_like(c)
    c.matrix("homography", (3, 3))
    _check_arena_numbers(c)
    c.matrix("centre", (2,))
    c.number("radius", 1e-3, 10.0)
    pos = c.matrix("camera_position", (3,), optional=True)
    if pos is not None and not pos[2] > 0:
        c.fail("camera_position", "must be above the floor (z > 0)")
    ranges = c.get("ball_hsv_ranges", optional=True)
    if ranges is not None:
        if not isinstance(ranges, list) or not ranges:
            c.fail("ball_hsv_ranges", "must be a non-empty list of [lower, upper] HSV triples")
        for i, r in enumerate(ranges):
            if not is_matrix(r, (2, 3)):
                c.fail(f"ball_hsv_ranges[{i}]", "must be [[h, s, v], [h, s, v]]")
            lo, hi = r
            if not (0 <= lo[0] <= hi[0] <= 179 and all(0 <= lo[j] <= hi[j] <= 255 for j in (1, 2))):
                c.fail(f"ball_hsv_ranges[{i}]", f"bounds out of order or range: {r}")
    c.number("ball_radius_m", 1e-3, 1.0, optional=True)
    c.number("residual_max_mm", 0.0, 1e4, optional=True)


def _validate_camera_like(c: Fields) -> None:
    c.matrix("camera_matrix", (3, 3))
    c.matrix("dist_coeffs", (-1,))
    c.matrix("image_size", (2,))


def _validate_joints(c: Fields) -> None:
    names = c.get("names")
    if not isinstance(names, list) or not names or not all(isinstance(n, str) for n in names):
        c.fail("names", "must be a non-empty list of joint names")
    if len(set(names)) != len(names):
        c.fail("names", f"must name each joint once, got {names}")
    n = len(names)
    for key in ("offsets", "lower", "upper"):
        c.matrix(key, (n,))
    dirs = c.matrix("directions", (n,))
    if any(d not in (1, -1) for d in dirs):
        c.fail("directions", f"must be +1 or -1 per joint, got {dirs}")
    for i, name in enumerate(names):
        if not c.data["lower"][i] < c.data["upper"][i]:
            c.fail("lower", f"of joint {name} must be below its upper limit")


def _validate_dynamics(c: Fields) -> None:
    from sim.servo_model import check_dynamics

    check_dynamics(c)


VALIDATORS: dict[str, Callable[[Fields], None]] = {
    "camera": check_camera_payload,
    "arena": _validate_arena,
    "joints": _validate_joints,
    "dynamics": _validate_dynamics,
}


def validate(kind: str, data: Any, where: str | None = None) -> dict[str, Any]:
    """Check a payload of the given kind; returns it or raises a one-line ``CalibrationError``."""
    if kind not in VALIDATORS:
        raise CalibrationError(f"unknown calibration kind {kind!r}; known: {', '.join(KINDS)}")
    checker = Fields(where or f"{kind} calibration", data, CalibrationError, name="data")
    VALIDATORS[kind](checker)
    return data


def _json_safe(value: Any) -> Any:
    """numpy arrays and scalars to plain lists and numbers (without importing numpy)."""
    if hasattr(value, "tolist"):
        return value.tolist()
    if isinstance(value, dict):
        return {str(k): _json_safe(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_json_safe(v) for v in value]
    return value


# ---- reading and writing -----------------------------------------------------------------
def save(kind: str, rig_id: str, data: dict[str, Any], directory: str | Path | None = None) -> Path:
    """Validate and atomically write a calibration; returns the file's path.

    A payload that fails validation raises before anything is written, so an existing good
    file is never replaced by a bad one.
    """
    path = calibration_path(kind, rig_id, directory)
    payload = _json_safe(data)
    validate(kind, payload, where=f"{path.name} (not written)")
    doc = {
        "schema": SCHEMA,
        "kind": kind,
        "version": VERSIONS[kind],
        "rig_id": rig_id,
        "created": datetime.now(UTC).isoformat(timespec="seconds"),
        "data": payload,
    }
    text = json.dumps(doc, indent=2, allow_nan=False) + "\n"
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        return atomic_write(path, text)
    except OSError as exc:  # named by the file asked for, never the temporary one
        what = "is a directory" if path.is_dir() else f"cannot be written ({exc.strerror or exc})"
        raise CalibrationError(f"{path} {what}: nothing written") from exc


# The arena file keeps a copy of the intrinsics it was fitted with (its homography is only
# valid for them); a camera.json beside it that differs by more than this, relative, means
# the camera was recalibrated after the arena. Guess: far above JSON round-off, far below
# what a recalibration changes (fx moves by 0.1-1% between two ChArUco calibrations).
INTRINSICS_RTOL = 1e-6


def intrinsics_mismatch(arena: dict[str, Any], camera: dict[str, Any]) -> str | None:
    """What differs between an arena payload's copy of the intrinsics and a camera payload
    (camera_matrix, dist_coeffs, image_size), in words, or None when they agree."""
    for name in ("image_size", "camera_matrix", "dist_coeffs"):
        a, c = _flat(arena[name]), _flat(camera[name])
        differ = len(a) != len(c)
        for x, y in zip(a, c, strict=False):
            differ = differ or abs(x - y) > INTRINSICS_RTOL * max(abs(x), abs(y), 1.0)
        if differ:
            if name == "camera_matrix":
                return (
                    f"camera_matrix differs (fx {a[0]:.2f} in the arena file, "
                    f"{c[0]:.2f} in camera.json)"
                )
            return (
                f"{name} differs ({arena[name]} in the arena file, {camera[name]} in camera.json)"
            )
    return None


def _flat(v: Any) -> list[float]:
    if isinstance(v, list | tuple):
        return [x for item in v for x in _flat(item)]
    return [float(v)]


def load_arena_file(path: str | Path) -> dict[str, Any]:
    """Read and validate an arena calibration, and check it against the camera calibration
    beside it (``camera.json`` in the same folder), when there is one: an arena fitted with
    other intrinsics than the camera's current ones puts the ball in the wrong place, so it is
    refused in one line naming what differs and the fix."""
    path = Path(path)
    data = load_file(path, "arena")
    camera_path = path.with_name("camera.json")
    if os.path.lexists(camera_path):  # a folder or a dangling link there is refused, not skipped
        camera = load_file(camera_path, "camera")
        why = intrinsics_mismatch(data, camera)
        if why is not None:
            rig = path.parent.name
            raise CalibrationError(
                f"{path}: made with another camera calibration than {camera_path} ({why}): "
                f"the camera was recalibrated after the arena; run `ergo calibrate arena "
                f"--rig-id {rig}` again"
            )
    return data


def load(kind: str, rig_id: str, directory: str | Path | None = None) -> dict[str, Any]:
    """Read and validate a calibration's payload (the ``data`` object); an arena's is also
    checked against the rig's camera calibration (``load_arena_file``)."""
    path = calibration_path(kind, rig_id, directory)
    return load_arena_file(path) if kind == "arena" else load_file(path, kind)


def load_file(path: str | Path, kind: str | None = None) -> dict[str, Any]:
    """Read and validate one calibration file; ``kind`` None accepts any kind."""
    return load_document(path, kind)["data"]


def file_sha256(path: str | Path) -> str:
    """The SHA-256 of a file's bytes, hex (what ``run.json`` records of each input file and
    ``ergo calibrate show`` prints)."""
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def created_at(doc: dict[str, Any]) -> datetime | None:
    """When a calibration document (``load_document``) was made, or None when its ``created``
    field is not an ISO-8601 time with a zone."""
    try:
        when = datetime.fromisoformat(str(doc.get("created")))
    except ValueError:
        return None
    return when if when.tzinfo is not None else None


def load_document(path: str | Path, kind: str | None = None) -> dict[str, Any]:
    """Read and validate one calibration file; returns the whole document (``schema``,
    ``kind``, ``version``, ``rig_id``, ``created``, ``data``): the envelope checked by
    ``robot.calibration_files.read_document``, the payload by its kind's validator."""
    doc = read_document(path, kind)
    validate(doc["kind"], doc["data"], where=f"{path}: data")
    return doc
