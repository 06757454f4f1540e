"""The ball in an arena calibration's frame: the floor's colour, the ball's blob, its HSV ranges.

- ``floor_colour``: the floor as the frame's dominant colour, of any colour, saturated or
  grey, white or black-ish, lit unevenly: a colour and every shade of it (a line through black
  in BGR), with the spread of its pixels about that line (``FloorColour``);
- ``find_saturated_blob``: the ball, a compact round blob of a saturated colour off the
  floor's line, of a ball's size where a ball can lie;
- ``sample_ball_hsv``: the ball's HSV range(s), sampled around a pixel on it.

Pixels: raw (distorted) pixels of a BGR frame, (u, v) = (column, row). Colours: 8-bit BGR
levels; hues in OpenCV's units (0..179, a circle).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calibration.store import CalibrationError
from sim.models.make_scene import BALL_RADIUS, INNER_RADIUS
from vision.rectify import ArenaModel, pixels_to_arena, undistort_points
from vision.tracker import HSVRange

GROW_HUE = 12  # hue units around the sampled mean when growing to the whole ball (guess)
MIN_FAMILY_PIXELS = 20  # a hue family needs this many saturated pixels (guess: a ball > 2.5 px)
MIN_FILL = 0.6  # a blob's area over its bounding circle's: a disc gives 0.79 (guess)
# How far outside where the twin's ball can lie (its centre between the kerb and the wall,
# sim/models/make_scene.py) a blob may map and still be taken for the ball, m: a real arena
# built by hand differs by a centimetre or two (guess).
PLACE_MARGIN_M = 0.02
# The ball's outline blends with what lies around it, over this many pixels: JPEG keeps one
# colour per 2 x 2 pixels (4:2:0 chroma, as webcams' MJPEG and OpenCV's encoder) and a lens
# blurs. Measured on the twin through JPEG: on a wood-brown floor (hue 14) the outline's
# blended hues took the ball's range down to hue 14, the whole floor; without them, to 25.
RIM_PX = 2

# ---- the floor's colour --------------------------------------------------------------------
# The floor's colour is found as the mode of a 3-D histogram of the frame's BGR levels in bins
# of this many levels (16 per channel: a floor's noise and JPEG's ripple stay within a bin or
# two, and a lighting gradient spreads it over a few; guess checked on the twin).
FLOOR_BIN = 16
# Pixels sampled for the floor's model, about (every k-th pixel of the region; a choice, for
# speed: the ring of a 640 x 480 frame, every other row and column of it (``ring_region``), is
# about 26 000 pixels, all taken).
FLOOR_SAMPLES = 60_000
# A shade of the floor is within this many standard deviations of the floor's line (the
# Mahalanobis distance of its offset from the line, 2-D): 3.5 keeps 99.8 % of a Gaussian spread
# (chi-square, 2 degrees of freedom).
FLOOR_GATE = 3.5
# A ball pixel is farther than this from the floor's line (standard deviations; guess: the
# gate, and as much again for a floor's texture, stains and JPEG's ringing at edges).
FLOOR_SIGMAS = 7.0
# The least spread counted about the floor's line, levels (one standard deviation): a
# rendered floor has none, a camera's 8-bit levels at least rounding (guess).
FLOOR_NOISE_LEVELS = 2.0
FLOOR_ITERATIONS = 10  # refinements of the floor's pixels: they settled in 2-7 on the tests' frames


@dataclass(frozen=True)
class FloorColour:
    """The floor's colour and every shade of it: the line through black along ``bgr`` in BGR
    space, with the spread of the floor's pixels about it. Lighting scales a colour's levels
    (exactly with a linear response, and with a power-law gamma), so a lighting gradient, a
    shadow or a lit patch of the floor stays on its line; noise, JPEG's ripple and the floor's
    texture move a pixel off it by the spread.

    Attributes:
        bgr: the floor's mean colour, shape (3,), BGR levels.
        basis: two unit vectors perpendicular to ``bgr``, shape (2, 3).
        cov: covariance of the floor's pixels' offsets from the line in that basis, shape
            (2, 2), levels^2 (at least ``FLOOR_NOISE_LEVELS``^2 on its diagonal).
        share: fraction of the sampled pixels that are the floor's (0..1).
    """

    bgr: np.ndarray
    basis: np.ndarray
    cov: np.ndarray
    share: float

    def distance(self, image: np.ndarray) -> np.ndarray:
        """How far each pixel of ``image`` (..., 3) BGR is from the floor's line, in standard
        deviations of the floor's spread (Mahalanobis, 2-D); shape (...)."""
        return _line_distance(np.asarray(image, np.float32), self.basis, self.cov)

    def hsv(self) -> tuple[int, int, int]:
        """The floor's mean colour in OpenCV's HSV (hue 0..179), for messages."""
        import cv2

        bgr = np.clip(np.rint(self.bgr), 0, 255).astype(np.uint8).reshape(1, 1, 3)
        h, s, v = cv2.cvtColor(bgr, cv2.COLOR_BGR2HSV)[0, 0]
        return int(h), int(s), int(v)


def _line_basis(bgr: np.ndarray) -> np.ndarray:
    """Two orthonormal vectors perpendicular to ``bgr`` (3,) (grey's when ``bgr`` is black),
    shape (2, 3)."""
    norm = float(np.linalg.norm(bgr))
    u = bgr / norm if norm >= 1.0 else np.full(3, 1 / np.sqrt(3))
    # rows 2 and 3 of an orthonormal basis whose first row is u
    q, _ = np.linalg.qr(np.column_stack([u, np.eye(3)[:, np.argsort(np.abs(u))[:2]]]))
    return q[:, 1:3].T


def _line_distance(pixels: np.ndarray, basis: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """Mahalanobis distance (covariance ``cov``, (2, 2)) of the offsets of ``pixels`` (..., 3)
    from the line perpendicular to ``basis`` (2, 3); shape (...)."""
    off = pixels @ basis.T
    inv = np.linalg.inv(cov)
    d2 = np.einsum("...i,ij,...j->...", off, inv, off)
    return np.sqrt(np.maximum(d2, 0.0))


def floor_colour(image: np.ndarray, region: np.ndarray | None = None) -> FloorColour:
    """The floor's colour: the dominant colour of ``image`` (within ``region``) and its shades.

    The mode of a 3-D histogram of the pixels' BGR levels (``FLOOR_BIN`` levels a bin, summed
    over 3 x 3 x 3 bins) gives a first set of floor pixels; then, until they settle, their mean
    gives the line, their offsets from it the spread (at least ``FLOOR_NOISE_LEVELS``), and the
    floor's pixels are those within ``FLOOR_GATE`` standard deviations of the line. Any colour
    works, saturated or not; the floor need only cover more of the region than anything else.

    Args:
        image: BGR frame (H, W, 3), uint8.
        region: where the floor is looked for, bool (H, W) (default: the whole frame), e.g.
            where the ball rolls (``ring_region``).
    """
    pixels = np.asarray(image).reshape(-1, 3)
    if region is not None:
        pixels = pixels[np.asarray(region, bool).reshape(-1)]
    if len(pixels) == 0:
        raise CalibrationError("no floor in view to tell the ball from: is the arena in view?")
    pixels = pixels[:: max(1, len(pixels) // FLOOR_SAMPLES)].astype(np.float32)
    n = 256 // FLOOR_BIN
    q = np.minimum(pixels.astype(int) // FLOOR_BIN, n - 1)
    hist = np.bincount((q[:, 0] * n + q[:, 1]) * n + q[:, 2], minlength=n**3).reshape(n, n, n)
    padded = np.pad(hist, 1)
    summed = sum(
        padded[i : i + n, j : j + n, k : k + n]
        for i in range(3)
        for j in range(3)
        for k in range(3)
    )
    mode = np.array(np.unravel_index(int(np.argmax(summed)), summed.shape))
    floor = np.all(np.abs(q - mode) <= 1, axis=1)
    noise = np.eye(2) * FLOOR_NOISE_LEVELS**2
    for _ in range(FLOOR_ITERATIONS):
        bgr = pixels[floor].mean(axis=0)
        basis = _line_basis(bgr)
        off = pixels[floor] @ basis.T
        cov = np.cov(off.T) + noise if len(off) > 2 else noise
        again = _line_distance(pixels, basis, cov) <= FLOOR_GATE
        if np.array_equal(again, floor) or not again.any():
            break
        floor = again
    return FloorColour(bgr.astype(np.float64), basis, cov, float(floor.mean()))


def ring_region(model: ArenaModel, shape: tuple[int, ...], step: int = 2) -> np.ndarray:
    """Pixels of a frame of ``shape`` (H, W, ...) that see the floor where the ball rolls:
    between the kerb around the arm's base (``INNER_RADIUS``) and the arena's wall
    (``model.radius``), bool (H, W); every ``step``-th row and column only (the rest False),
    for speed."""
    h, w = shape[:2]
    vv, uu = np.mgrid[0:h:step, 0:w:step]
    xy = pixels_to_arena(model, np.column_stack([uu.ravel(), vv.ravel()]).astype(np.float64))
    r = np.linalg.norm(xy - model.centre, axis=1)
    region = np.zeros((h, w), bool)
    region[vv.ravel(), uu.ravel()] = (r >= INNER_RADIUS) & (r <= model.radius)
    return region


# ---- the ball ------------------------------------------------------------------------------
def hue_families(hues: np.ndarray) -> list[int]:
    """The main hues among saturated pixels (OpenCV hues 0..179, a circle), most common first:
    the peaks of their histogram (smoothed over 5 units) with at least ``MIN_FAMILY_PIXELS``
    pixels, each the highest within ``GROW_HUE`` units around it. Two objects of different
    colours that touch in the image (the ball against the arm's orange tool) are two
    families."""
    hist = np.bincount(np.asarray(hues, int).ravel() % 180, minlength=180).astype(float)
    smooth = sum(np.roll(hist, k) for k in range(-2, 3))
    peaks = []
    for h in np.argsort(-smooth, kind="stable"):
        if smooth[h] < MIN_FAMILY_PIXELS:
            break
        if all(min(abs(h - p), 180 - abs(h - p)) > GROW_HUE for p in peaks):
            peaks.append(int(h))
    return peaks


def expected_ball_area(
    model: ArenaModel, pixel: tuple[float, float], ball_radius_m: float
) -> tuple[float, float] | None:
    """Where a ball seen at ``pixel`` would lie and how big it would look: (its centre's
    distance from the arena's centre, m; its image area, px^2), or None without the camera's
    position. A sphere of radius R at distance D from the camera, seen at an angle t off the
    optical axis, images as an ellipse of semi-axes f tan(a) / cos(t) and f tan(a) / cos^2(t),
    sin(a) = R / D (pinhole; distortion ignored)."""
    if model.camera_position is None:
        return None
    xy = pixels_to_arena(model, np.asarray([pixel], np.float64), height=ball_radius_m)[0]
    d = float(np.linalg.norm(np.array([*xy, ball_radius_m]) - model.camera_position))
    if d <= ball_radius_m:
        return None
    und = undistort_points(np.asarray([pixel], np.float64), model.camera_matrix, model.dist_coeffs)
    ray = np.linalg.solve(model.camera_matrix, np.array([*und[0], 1.0]))
    cos_t = 1.0 / float(np.linalg.norm(ray))
    tan_a = ball_radius_m / np.sqrt(d**2 - ball_radius_m**2)
    fx, fy = float(model.camera_matrix[0, 0]), float(model.camera_matrix[1, 1])
    area = np.pi * fx * fy * tan_a**2 / cos_t**3
    return float(np.linalg.norm(xy - model.centre)), float(area)


def find_saturated_blob(
    image: np.ndarray,
    model: ArenaModel | None = None,
    ball_radius_m: float = BALL_RADIUS,
    min_saturation: int = 90,
) -> tuple[float, float]:
    """Pixel (u, v) of the ball: the most ball-like round blob of a saturated colour that is
    not a shade of the floor's.

    The floor's colour is the dominant one where the ball rolls (``floor_colour`` over
    ``ring_region``; over the whole frame without a model), of any colour. Saturated pixels
    (S >= ``min_saturation``, V >= 60) farther than ``FLOOR_SIGMAS`` from the floor's line are
    split into hue families (``hue_families``: each pixel goes to the nearest family within
    ``GROW_HUE``), so that the ball and an object of another colour touching it (the arm's
    orange tool) are separate blobs. Blobs that are not round (fill under ``MIN_FILL``) are
    left out. With an arena model that knows the camera's position, so are blobs where no ball
    can lie (a ball's centre between the kerb around the arm's base and the wall:
    ``INNER_RADIUS`` + R .. radius - R, with ``PLACE_MARGIN_M``), and the blob whose area is
    nearest a ball's there (``expected_ball_area``) is chosen: the tool seen end-on from above
    is round too, but nearer the camera, hence larger. Without one, the largest round blob.

    Raises:
        CalibrationError: no saturated colour, or no blob that can be the ball (one line,
            naming the floor's colour).
    """
    import cv2

    hsv = cv2.cvtColor(image, cv2.COLOR_BGR2HSV)
    sat = (hsv[..., 1] >= min_saturation) & (hsv[..., 2] >= 60)
    if not sat.any():
        raise CalibrationError("no saturated colour in the frame: is the ball in view?")
    floor = floor_colour(image, ring_region(model, image.shape) if model is not None else None)
    candidate = sat & (floor.distance(image) > FLOOR_SIGMAS)
    hue = hsv[..., 0].astype(int)
    families = hue_families(hue[candidate])
    if families:
        distances = np.stack([_hue_distance(hue, p) for p in families])
        nearest = np.argmin(distances, axis=0)
        candidate &= np.min(distances, axis=0) <= GROW_HUE
    best, best_score = None, np.inf
    for k in range(len(families)):
        mask = (candidate & (nearest == k)).astype(np.uint8) * 255
        mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, np.ones((3, 3), np.uint8))
        n, _, stats, centroids = cv2.connectedComponentsWithStats(mask)
        for i in range(1, n):
            area = float(stats[i, cv2.CC_STAT_AREA])
            w, h = stats[i, cv2.CC_STAT_WIDTH], stats[i, cv2.CC_STAT_HEIGHT]
            if area < MIN_FAMILY_PIXELS or area / (np.pi * (max(w, h) / 2) ** 2) < MIN_FILL:
                continue
            centre = (float(centroids[i][0]), float(centroids[i][1]))
            expected = expected_ball_area(model, centre, ball_radius_m) if model else None
            if expected is None:
                score = -area
            else:
                r, ball_area = expected
                inner = INNER_RADIUS + ball_radius_m - PLACE_MARGIN_M
                if not inner <= r <= model.radius - ball_radius_m + PLACE_MARGIN_M:
                    continue
                score = abs(np.log(area / ball_area))
            if score < best_score:
                best, best_score = centre, score
    if best is None:
        h, s, v = floor.hsv()
        raise CalibrationError(
            f"no round saturated blob of another colour than the floor (HSV {h}, {s}, {v}) "
            "where a ball can lie: is the ball in view, between the kerb and the wall? Or give "
            "--ball-pixel U,V"
        )
    return best


def _hue_distance(hue: np.ndarray, ref: int) -> np.ndarray:
    """Circular distance of OpenCV hues (0..179) from ``ref``, same shape, hue units."""
    d = np.abs(np.asarray(hue, int) - int(ref))
    return np.minimum(d, 180 - d)


def _circular_mean_hue(hue: np.ndarray) -> int:
    """Mean of OpenCV hues (0..179, a circle), as an int in 0..179."""
    ang = hue.astype(float) * (2 * np.pi / 180)
    deg = float(np.degrees(np.arctan2(np.sin(ang).mean(), np.cos(ang).mean())))
    return round(deg / 2) % 180


def _dilated_disc(disc: np.ndarray, radius: float) -> np.ndarray:
    """Pixels within ``radius`` of the disc's centre: caps how far the region may grow."""
    ys, xs = np.nonzero(disc)
    cu, cv_ = xs.mean(), ys.mean()
    yy, xx = np.mgrid[0 : disc.shape[0], 0 : disc.shape[1]]
    return (xx - cu) ** 2 + (yy - cv_) ** 2 <= radius**2


def sample_ball_hsv(
    image: np.ndarray,
    pixel: tuple[float, float],
    radius_px: float = 8.0,
    hue_margin: int = 4,
) -> list[HSVRange]:
    """HSV range(s) of the ball from a disc of pixels around ``pixel`` (on the ball).

    The disc gives the hue family and the saturation and value lower bounds (half and 0.3
    times their 2nd percentiles, floored at 40 and 50; upper bounds 255 for highlights); the
    sample then grows over the connected region of that colour around the pixel (the whole
    ball, rim included, up to six disc radii) and the hue range spans its 1st to 99th
    percentile widened by ``hue_margin``. A hue range crossing 0/179 (red) is split in two.
    Margins are guesses checked on the twin.

    Args:
        image: BGR frame (H, W, 3).
        pixel: (u, v) on the ball, raw pixels.
        radius_px: sampling disc radius, pixels (keep it inside the ball).
    """
    import cv2

    hsv = cv2.cvtColor(image, cv2.COLOR_BGR2HSV)
    h, w = hsv.shape[:2]
    u, v = pixel
    if not (0 <= u < w and 0 <= v < h):
        raise CalibrationError(f"ball pixel ({u:.0f}, {v:.0f}) is outside the {w}x{h} frame")
    yy, xx = np.mgrid[0:h, 0:w]
    disc = (xx - u) ** 2 + (yy - v) ** 2 <= radius_px**2
    px = hsv[disc].astype(int)
    if len(px) < 5:
        raise CalibrationError("too few pixels sampled around the ball pixel")
    if np.percentile(px[:, 1], 50) < 60:
        raise CalibrationError(
            f"the pixels around ({u:.0f}, {v:.0f}) are not saturated (S median "
            f"{np.percentile(px[:, 1], 50):.0f}): is that the ball?"
        )
    # The disc sees the ball's lit middle; its rim is darker (same hue family, lower value),
    # so the lower bounds are generous fractions of what was sampled (guesses checked on the
    # twin).
    s_lo = max(40, int(0.5 * np.percentile(px[:, 1], 2)))
    v_lo = max(50, int(0.3 * np.percentile(px[:, 2], 2)))
    mean = _circular_mean_hue(px[:, 0])
    # Grow the sample to the whole ball: the connected region around the pixel whose hue is
    # within GROW_HUE of the disc's mean and that passes the S and V bounds.
    dh = np.abs(hsv[..., 0].astype(int) - mean)
    dh = np.minimum(dh, 180 - dh)
    loose = ((dh <= GROW_HUE) & (hsv[..., 1] >= s_lo) & (hsv[..., 2] >= v_lo)).astype(np.uint8)
    _, labels = cv2.connectedComponents(loose)
    label = labels[min(h - 1, int(v + 0.5)), min(w - 1, int(u + 0.5))]
    region = (labels == label) & (label > 0) & (disc | _dilated_disc(disc, radius_px * 6))
    # The hue range from the region less its outline, where the ball's colour blends with
    # what lies around it (the floor, the tool) in the lens's blur and JPEG's chroma.
    kernel = np.ones((2 * RIM_PX + 1, 2 * RIM_PX + 1), np.uint8)
    core = cv2.erode(region.astype(np.uint8), kernel) > 0
    hue = hsv[..., 0][core | disc].astype(int)
    shifted = (hue - mean + 90) % 180  # the sample's mean at 90, away from the 0/180 seam
    lo = int(np.floor(np.percentile(shifted, 1))) - hue_margin + mean - 90
    hi = int(np.ceil(np.percentile(shifted, 99))) + hue_margin + mean - 90
    if hi - lo >= 179:
        return [HSVRange((0, s_lo, v_lo), (179, 255, 255))]
    lo_m, hi_m = lo % 180, hi % 180
    if lo_m <= hi_m:
        return [HSVRange((lo_m, s_lo, v_lo), (hi_m, 255, 255))]
    return [
        HSVRange((0, s_lo, v_lo), (hi_m, 255, 255)),
        HSVRange((lo_m, s_lo, v_lo), (179, 255, 255)),
    ]
