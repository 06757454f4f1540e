"""From camera pixels to metres on the arena: undistortion, the arena-plane homography, and the
arena's polar coordinates.

Conventions:
- Pixels (u, v): column and row, OpenCV's convention (centre of the top-left pixel at (0, 0)).
  "Raw" pixels are those of the camera's frames; "undistorted" pixels are those of the same
  camera matrix without lens distortion.
- Arena coordinates (x, y): metres on the arena floor, in the frame the calibration markers'
  positions were given in (on the rig and in the twin: origin at the arm's base, x to the
  right of the overhead image, y up it, z up from the floor).
- Angles in radians; theta = atan2(y - cy, x - cx) in (-pi, pi].

Everything here is a pure function of arrays and an ``ArenaModel``; nothing reads a camera.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np


def _as_points(points: np.ndarray | list | tuple) -> np.ndarray:
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim == 1:
        pts = pts.reshape(1, -1)
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise ValueError(f"points must have shape (N, 2), got {pts.shape}")
    return pts


@dataclass(frozen=True)
class ArenaModel:
    """Everything needed to turn a camera pixel into a position on the arena.

    Attributes:
        camera_matrix: intrinsics, shape (3, 3), pixels.
        dist_coeffs: OpenCV distortion coefficients (k1, k2, p1, p2[, k3 ...]), shape (k,).
        image_size: (width, height) of the camera's frames, pixels.
        homography: shape (3, 3), maps undistorted pixels (u, v, 1) to arena (x, y, 1) in
            metres on the floor plane z = 0 (up to scale).
        centre: arena centre (x, y), shape (2,), metres.
        radius: arena radius, metres (the outcome metric's bounding square is centre +- radius).
        camera_position: the camera's optical centre (x, y, z) in arena coordinates, shape (3,),
            metres, or None when the intrinsics were not known well enough to recover it.
            Needed to place points that are not on the floor (the ball's centre is one radius
            above it: ignoring that shifts a ball 0.15 m off the axis by about 9 mm at 0.55 m).
    """

    camera_matrix: np.ndarray
    dist_coeffs: np.ndarray
    image_size: tuple[int, int]
    homography: np.ndarray
    centre: np.ndarray
    radius: float
    camera_position: np.ndarray | None = field(default=None)

    def __post_init__(self) -> None:
        k = np.asarray(self.camera_matrix, dtype=np.float64)
        h = np.asarray(self.homography, dtype=np.float64)
        c = np.asarray(self.centre, dtype=np.float64).reshape(-1)
        if k.shape != (3, 3):
            raise ValueError(f"camera_matrix must be 3x3, got {k.shape}")
        if h.shape != (3, 3) or not np.all(np.isfinite(h)):
            raise ValueError(f"homography must be a finite 3x3 matrix, got shape {h.shape}")
        if c.shape != (2,):
            raise ValueError(f"centre must have 2 values, got {c.shape}")
        if not self.radius > 0:
            raise ValueError(f"radius must be > 0 m, got {self.radius}")
        object.__setattr__(self, "camera_matrix", k)
        object.__setattr__(self, "homography", h / h[2, 2])
        object.__setattr__(self, "centre", c)
        object.__setattr__(
            self, "dist_coeffs", np.asarray(self.dist_coeffs, dtype=np.float64).reshape(-1)
        )
        object.__setattr__(self, "image_size", (int(self.image_size[0]), int(self.image_size[1])))
        object.__setattr__(self, "radius", float(self.radius))
        if self.camera_position is not None:
            p = np.asarray(self.camera_position, dtype=np.float64).reshape(-1)
            if p.shape != (3,) or not p[2] > 0:
                raise ValueError(f"camera_position must be (x, y, z > 0) metres, got {p}")
            object.__setattr__(self, "camera_position", p)

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-able form (lists of floats)."""
        return {
            "camera_matrix": self.camera_matrix.tolist(),
            "dist_coeffs": self.dist_coeffs.tolist(),
            "image_size": list(self.image_size),
            "homography": self.homography.tolist(),
            "centre": self.centre.tolist(),
            "radius": self.radius,
            "camera_position": (
                None if self.camera_position is None else self.camera_position.tolist()
            ),
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> ArenaModel:
        return cls(
            camera_matrix=np.asarray(d["camera_matrix"], dtype=np.float64),
            dist_coeffs=np.asarray(d["dist_coeffs"], dtype=np.float64),
            image_size=tuple(d["image_size"]),
            homography=np.asarray(d["homography"], dtype=np.float64),
            centre=np.asarray(d["centre"], dtype=np.float64),
            radius=float(d["radius"]),
            camera_position=(
                None if d.get("camera_position") is None else np.asarray(d["camera_position"])
            ),
        )


# ---- undistortion --------------------------------------------------------------------------
def undistort_points(
    pixels: np.ndarray, camera_matrix: np.ndarray, dist_coeffs: np.ndarray
) -> np.ndarray:
    """Raw pixels -> undistorted pixels of the same camera matrix.

    Args:
        pixels: shape (N, 2), raw pixels.
        camera_matrix: shape (3, 3).
        dist_coeffs: shape (k,).

    Returns:
        shape (N, 2), undistorted pixels.
    """
    import cv2

    pts = _as_points(pixels)
    if not np.any(dist_coeffs):
        return pts.copy()
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-10)
    out = cv2.undistortPoints(
        pts.reshape(-1, 1, 2),
        np.asarray(camera_matrix, np.float64),
        np.asarray(dist_coeffs, np.float64),
        None,
        None,
        np.asarray(camera_matrix, np.float64),
        criteria,
    )
    return out.reshape(-1, 2)


def distort_points(
    pixels: np.ndarray, camera_matrix: np.ndarray, dist_coeffs: np.ndarray
) -> np.ndarray:
    """Undistorted pixels -> raw pixels (the inverse of ``undistort_points``), shapes (N, 2)."""
    import cv2

    pts = _as_points(pixels)
    if not np.any(dist_coeffs):
        return pts.copy()
    k = np.asarray(camera_matrix, np.float64)
    rays = np.linalg.solve(k, np.column_stack([pts, np.ones(len(pts))]).T).T
    out, _ = cv2.projectPoints(
        rays.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), k, np.asarray(dist_coeffs, np.float64)
    )
    return out.reshape(-1, 2)


def undistort_image(
    image: np.ndarray, camera_matrix: np.ndarray, dist_coeffs: np.ndarray
) -> np.ndarray:
    """The frame as an ideal pinhole camera with the same camera matrix would see it; same
    shape and dtype as ``image`` (H, W[, C])."""
    import cv2

    if not np.any(dist_coeffs):
        return image.copy()
    return cv2.undistort(image, camera_matrix, dist_coeffs, None, camera_matrix)


# ---- the arena plane -----------------------------------------------------------------------
def fit_homography(undistorted_pixels: np.ndarray, arena_xy: np.ndarray) -> np.ndarray:
    """Least-squares homography from >= 4 point pairs (no outlier rejection: calibration
    points are trusted), shape (3, 3), mapping undistorted pixels to arena metres.

    Args:
        undistorted_pixels: shape (N, 2), pixels.
        arena_xy: shape (N, 2), metres.
    """
    import cv2

    src = _as_points(undistorted_pixels)
    dst = _as_points(arena_xy)
    if len(src) != len(dst) or len(src) < 4:
        raise ValueError(f"need >= 4 point pairs of equal count, got {len(src)} and {len(dst)}")
    h, _ = cv2.findHomography(src, dst, 0)
    if h is None or not np.all(np.isfinite(h)):
        raise ValueError("the points do not define a homography (collinear or repeated?)")
    return h / h[2, 2]


def apply_homography(h: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Map points (N, 2) through a 3x3 homography; returns (N, 2)."""
    pts = _as_points(points)
    ph = np.column_stack([pts, np.ones(len(pts))]) @ np.asarray(h, np.float64).T
    return ph[:, :2] / ph[:, 2:3]


def estimate_camera_position(
    raw_pixels: np.ndarray,
    arena_xy: np.ndarray,
    camera_matrix: np.ndarray,
    dist_coeffs: np.ndarray,
) -> np.ndarray:
    """The camera's optical centre in arena coordinates from >= 4 floor points (planar PnP).

    Args:
        raw_pixels: shape (N, 2), raw pixels of points on the floor.
        arena_xy: shape (N, 2), their arena positions, metres (z = 0).
        camera_matrix: shape (3, 3); dist_coeffs: shape (k,).

    Returns:
        shape (3,), metres; z is the camera's height above the floor.
    """
    import cv2

    px = _as_points(raw_pixels)
    xy = _as_points(arena_xy)
    obj = np.column_stack([xy, np.zeros(len(xy))])
    k = np.asarray(camera_matrix, np.float64)
    d = np.asarray(dist_coeffs, np.float64)
    # SQPnP (a global solver): IPPE returned a wrong pose for an exactly fronto-parallel view
    # (the twin's straight-down camera) in a check on this OpenCV 5.0 build.
    ok, rvec, tvec = cv2.solvePnP(obj, px, k, d, flags=cv2.SOLVEPNP_SQPNP)
    if not ok:
        raise ValueError("solvePnP failed: the floor points do not fix the camera's pose")
    rvec, tvec = cv2.solvePnPRefineLM(obj, px, k, d, rvec, tvec)
    r, _ = cv2.Rodrigues(rvec)
    pos = (-r.T @ tvec).reshape(3)
    if pos[2] <= 0:
        raise ValueError(f"the camera came out below the floor ({pos}): points mislabelled?")
    return pos


def pixels_to_arena(model: ArenaModel, pixels: np.ndarray, height: float = 0.0) -> np.ndarray:
    """Raw pixels -> arena (x, y) of points at ``height`` metres above the floor.

    Args:
        model: the arena calibration.
        pixels: shape (N, 2), raw pixels.
        height: height of the observed points above the floor, metres (0 for floor points; a
            ball's radius for its centre). Needs ``model.camera_position`` unless 0.

    Returns:
        shape (N, 2), metres.
    """
    und = undistort_points(pixels, model.camera_matrix, model.dist_coeffs)
    floor = apply_homography(model.homography, und)
    if height == 0.0:
        return floor
    if model.camera_position is None:
        raise ValueError(
            "points above the floor need the camera's position: calibrate the arena with the "
            "camera's intrinsics"
        )
    c = model.camera_position
    # The ray from the camera through the floor point meets z = height at this fraction.
    return c[:2] + (floor - c[:2]) * (c[2] - height) / c[2]


def arena_to_pixels(model: ArenaModel, arena_xy: np.ndarray, height: float = 0.0) -> np.ndarray:
    """Arena (x, y) of points at ``height`` metres above the floor -> raw pixels, (N, 2)."""
    xy = _as_points(arena_xy)
    if height != 0.0:
        if model.camera_position is None:
            raise ValueError("points above the floor need the camera's position")
        c = model.camera_position
        xy = c[:2] + (xy - c[:2]) * c[2] / (c[2] - height)
    und = apply_homography(np.linalg.inv(model.homography), xy)
    return distort_points(und, model.camera_matrix, model.dist_coeffs)


def metres_per_pixel(model: ArenaModel, pixel: np.ndarray | None = None) -> float:
    """Approximate size of one raw pixel on the floor at ``pixel`` (default: the arena centre's
    image), metres."""
    if pixel is None:
        pixel = arena_to_pixels(model, model.centre)[0]
    p = np.asarray(pixel, dtype=np.float64).reshape(2)
    pts = pixels_to_arena(model, np.array([p, p + np.array((1.0, 0.0)), p + np.array((0.0, 1.0))]))
    return float((np.linalg.norm(pts[1] - pts[0]) + np.linalg.norm(pts[2] - pts[0])) / 2)


# ---- a metric top-down image ---------------------------------------------------------------
def top_down_maps(
    model: ArenaModel, px_per_m: float, margin: float = 0.0
) -> tuple[np.ndarray, np.ndarray]:
    """Remap tables for a metric top-down image of the arena's bounding square.

    Output pixel (row i, column j) shows arena point x = cx - R' + (j + 0.5) / s,
    y = cy + R' - (i + 0.5) / s with s = ``px_per_m`` and R' = radius + ``margin`` (image up =
    arena +y). The output's side is round(2 R' s) pixels.

    Returns:
        (map_x, map_y), each shape (side, side), float32: raw source pixels.
    """
    half = model.radius + margin
    side = max(1, round(2 * half * px_per_m))
    j, i = np.meshgrid(np.arange(side) + 0.5, np.arange(side) + 0.5)
    x = model.centre[0] - half + j / px_per_m
    y = model.centre[1] + half - i / px_per_m
    raw = arena_to_pixels(model, np.column_stack([x.ravel(), y.ravel()]))
    return (
        raw[:, 0].reshape(side, side).astype(np.float32),
        raw[:, 1].reshape(side, side).astype(np.float32),
    )


def top_down(
    image: np.ndarray, model: ArenaModel, px_per_m: float = 500.0, margin: float = 0.0
) -> np.ndarray:
    """A metric top-down image of the arena (undistortion and homography in one remap).

    Args:
        image: raw frame, shape (H, W[, C]).
        model: the arena calibration.
        px_per_m: output scale, pixels per metre (500: 2 mm per pixel; a choice, not a
            measurement).
        margin: extra metres shown around the arena's bounding square.

    Returns:
        shape (S, S[, C]) with S = round(2 (radius + margin) px_per_m); outside the frame: black.
    """
    import cv2

    map_x, map_y = top_down_maps(model, px_per_m, margin)
    return cv2.remap(image, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)


# ---- polar coordinates around the arena centre -------------------------------------------
def polar(xy: np.ndarray, centre: np.ndarray = (0.0, 0.0)) -> tuple[np.ndarray, np.ndarray]:
    """(r, theta) of points around ``centre``.

    Args:
        xy: shape (N, 2) or (2,), metres.
        centre: shape (2,), metres.

    Returns:
        r in metres and theta in (-pi, pi] radians, each shape (N,) (or scalars for one point).
    """
    p = np.asarray(xy, dtype=np.float64)
    d = p - np.asarray(centre, dtype=np.float64)
    r = np.hypot(d[..., 0], d[..., 1])
    theta = np.arctan2(d[..., 1], d[..., 0])
    return r, theta


def polar_features(xy: np.ndarray, centre: np.ndarray = (0.0, 0.0)) -> np.ndarray:
    """The wrap-safe polar form (r, cos theta, sin theta), continuous across theta = +-pi
    (the paper's theta jumped from 2 pi to 0 there).

    Args:
        xy: shape (N, 2) or (2,), metres.
        centre: shape (2,), metres.

    Returns:
        shape (N, 3) or (3,): r in metres, then cos and sin (unitless). At r = 0 the angle is
        undefined; cos = 1, sin = 0 there.
    """
    r, theta = polar(xy, centre)
    return np.stack([r, np.cos(theta), np.sin(theta)], axis=-1)
