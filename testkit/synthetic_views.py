"""Synthetic camera views of a flat printed target (a ChArUco board, a marker sheet), for tests
and for trying the calibration without a camera.

A view is made by ray casting: for every pixel of the distorted output image, the pixel is
undistorted with the camera model, its ray intersected with the target's plane, and the
target image sampled there (with 2x2 supersampling, then area-averaged). The target lies in its
own plane z = 0 with x to the right and y down its image, origin at its top-left corner, which
is OpenCV's ChArUco object-point convention.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from vision.rectify import undistort_points


def render_plane_view(
    target: np.ndarray,
    target_px_per_m: float,
    camera_matrix: np.ndarray,
    dist_coeffs: np.ndarray,
    rvec: np.ndarray,
    tvec: np.ndarray,
    size: tuple[int, int],
    background: int = 96,
    supersample: int = 2,
    origin_px: tuple[float, float] = (0.0, 0.0),
) -> np.ndarray:
    """What a camera sees of a flat target.

    Args:
        target: the target's image, shape (Ht, Wt) or (Ht, Wt, 3), uint8; pixel (i, j) covers
            x in [j, j+1] / target_px_per_m, y in [i, i+1] / target_px_per_m metres.
        target_px_per_m: the target image's scale, pixels per metre.
        camera_matrix: shape (3, 3), pixels; dist_coeffs: OpenCV coefficients, shape (k,).
        rvec, tvec: target-to-camera pose (Rodrigues vector, translation in metres), shape (3,).
        size: (height, width) of the output, pixels.
        background: grey level where the ray misses the target or looks at its back.
        supersample: rays per pixel side.
        origin_px: where the target's origin (0, 0) lies in ``target``, pixels from its
            top-left corner (e.g. a white margin's width).

    Returns:
        shape (H, W) or (H, W, 3) like ``target``, uint8.
    """
    import cv2

    h, w = size
    s = int(supersample)
    rays = pixel_rays(camera_matrix, dist_coeffs, size, s)  # (H s, W s, 2), normalised
    r, _ = cv2.Rodrigues(np.asarray(rvec, np.float64))
    t = np.asarray(tvec, np.float64).reshape(3)
    # A target point (a, b, 0) is at a r1 + b r2 + t in the camera: the plane is a homography
    # of the normalised rays, scaled to target pixels (centres at integers).
    plane_to_ray = np.column_stack([r[:, 0], r[:, 1], t])
    ox, oy = origin_px
    scale = np.array([[target_px_per_m, 0, ox - 0.5], [0, target_px_per_m, oy - 0.5], [0, 0, 1.0]])
    ray_to_target = scale @ np.linalg.inv(plane_to_ray)
    maps = cv2.perspectiveTransform(rays, ray_to_target)
    # The ray meets the plane at depth 1 / w3: behind the camera when w3 <= 0.
    inv = np.linalg.inv(plane_to_ray)
    w3 = inv[2, 0] * rays[..., 0] + inv[2, 1] * rays[..., 1] + inv[2, 2]
    behind = w3 <= 0
    maps[behind] = -1e6
    big = cv2.remap(
        target,
        maps,
        None,
        cv2.INTER_LINEAR,
        borderMode=cv2.BORDER_CONSTANT,
        borderValue=(background,) * 3 if target.ndim == 3 else background,
    )
    if s == 1:
        return big
    return cv2.resize(big, (w, h), interpolation=cv2.INTER_AREA)


_RAYS_CACHE: dict[bytes, np.ndarray] = {}


def pixel_rays(
    camera_matrix: np.ndarray, dist_coeffs: np.ndarray, size: tuple[int, int], supersample: int
) -> np.ndarray:
    """Normalised viewing rays (x, y) (the ray is (x, y, 1) in camera coordinates) of every
    sample of the supersampled output image, shape (H s, W s, 2), float32; cached per camera (the
    iterative undistortion of a whole image takes about a second, the views share it)."""
    k = np.asarray(camera_matrix, np.float64)
    d = np.asarray(dist_coeffs, np.float64).reshape(-1)
    key = k.tobytes() + d.tobytes() + np.array([*size, supersample]).tobytes()
    rays = _RAYS_CACHE.get(key)
    if rays is None:
        h, w = size
        s = int(supersample)
        offs = (np.arange(s) + 0.5) / s - 0.5  # sample offsets, pixel centres at integers
        us = (np.arange(w)[:, None] + offs[None]).ravel()
        vs = (np.arange(h)[:, None] + offs[None]).ravel()
        uu, vv = np.meshgrid(us, vs)
        und = undistort_points(np.column_stack([uu.ravel(), vv.ravel()]), k, d)
        rays = np.linalg.solve(k, np.column_stack([und, np.ones(len(und))]).T)
        rays = (rays[:2] / rays[2]).T.reshape(h * s, w * s, 2).astype(np.float32)
        _RAYS_CACHE.clear()  # keep one camera: the arrays are tens of MB
        _RAYS_CACHE[key] = rays
    return rays


def look_at_pose(
    target_centre: np.ndarray, camera_position: np.ndarray, roll: float = 0.0
) -> tuple[np.ndarray, np.ndarray]:
    """Target-to-camera pose of a camera at ``camera_position`` looking at ``target_centre``
    (both in target coordinates, metres, shape (3,)); ``roll`` in radians about the view axis.

    Returns:
        (rvec, tvec), each shape (3,).
    """
    import cv2

    c = np.asarray(camera_position, np.float64)
    z = np.asarray(target_centre, np.float64) - c
    z /= np.linalg.norm(z)
    up = np.array([0.0, -1.0, 0.0]) if abs(z[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
    x = np.cross(up, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    r_cam_to_target = np.column_stack([x, y, z])
    cr, sr = np.cos(roll), np.sin(roll)
    roll_m = np.array([[cr, -sr, 0.0], [sr, cr, 0.0], [0.0, 0.0, 1.0]])
    r = (r_cam_to_target @ roll_m).T  # target -> camera
    t = -r @ c
    rvec, _ = cv2.Rodrigues(r)
    return rvec.reshape(3), t


def random_views(
    target_size_m: tuple[float, float],
    n: int,
    seed: int = 0,
    distance: tuple[float, float] = (0.25, 0.40),
    max_tilt_deg: float = 35.0,
    aim_spread: float = 0.5,
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Well-spread (rvec, tvec) poses looking at a target of (width, height) metres.

    Cameras stand at random distances in ``distance`` (m), tilted up to ``max_tilt_deg`` from
    the target's normal in random directions, rolled by up to 30 degrees, and aimed at points
    up to ``aim_spread`` target sizes off its centre so that it lands in all parts of the
    image; seeded.
    """
    rng = np.random.default_rng(seed)
    tw, th = target_size_m
    poses = []
    for _ in range(n):
        dist = rng.uniform(*distance)
        tilt = np.radians(rng.uniform(5.0, max_tilt_deg))
        azim = rng.uniform(-np.pi, np.pi)
        aim = np.array(
            [
                (0.5 + rng.uniform(-aim_spread, aim_spread)) * tw,
                (0.5 + rng.uniform(-aim_spread, aim_spread)) * th,
                0.0,
            ]
        )
        # The camera is on the printed side: z < 0 in target coordinates (z points into it).
        offset = dist * np.array(
            [np.sin(tilt) * np.cos(azim), np.sin(tilt) * np.sin(azim), -np.cos(tilt)]
        )
        poses.append(look_at_pose(aim, aim + offset, roll=rng.uniform(-0.5, 0.5)))
    return poses


def board_images(
    spec: Any,
    camera_matrix: np.ndarray,
    dist_coeffs: np.ndarray,
    size: tuple[int, int],
    n: int,
    seed: int = 0,
    px_per_m: float = 4000.0,
    margin_squares: float = 1.0,
    noise: float = 2.0,
    distance: tuple[float, float] = (0.25, 0.40),
    aim_spread: float = 0.5,
) -> list[np.ndarray]:
    """``n`` grey views (H, W) uint8 of a printed board (``spec``: a ChArUco ``BoardSpec`` or a
    ``ChessboardSpec``, whose ``image`` is the print) through a known camera, at
    ``random_views`` poses (seeded), with Gaussian pixel noise of ``noise`` grey levels.

    Args:
        size: (height, width) of the views, pixels.
        px_per_m: the print's texture resolution (4000: 0.25 mm a texel).
        margin_squares: white paper around the board, in squares.
        distance, aim_spread: as ``random_views`` (a chessboard must be seen whole: farther,
            aimed closer to its centre).
    """
    margin = round(margin_squares * spec.square_m * px_per_m)
    target = spec.image(px_per_m, margin_px=margin)
    rng = np.random.default_rng(seed + 1)
    out = []
    for rvec, tvec in random_views(spec.size_m, n, seed, distance, aim_spread=aim_spread):
        img = render_plane_view(
            target, px_per_m, camera_matrix, dist_coeffs, rvec, tvec, size,
            origin_px=(margin, margin),
        )  # fmt: skip
        out.append(np.clip(img + rng.normal(0.0, noise, img.shape), 0, 255).astype(np.uint8))
    return out
