"""A ball's outline as a circle: the circle that the visible boundary of a blob follows, fitted
robustly (points off it left out), and how much of the ball that circle says is there.

The tracker (``vision.tracker``) uses it for a ball-coloured blob that fails the round-blob
test (its area against its minimum enclosing circle's): a ball against the arena's wall comes
out of a JPEG stream with a spur or a flattened side where its edge blends with the wall's
(the wall's grey takes the ball's chroma over a pixel or two; a dark band loses the ball's
rim), and a ball cut by an edge keeps an arc of its outline. The fitted circle's centre is the
ball's, where its centroid is pulled by the spur or the missing part.

Pixels: (u, v) = (column, row), raw pixels; an outline's points are the centres of a blob's
boundary pixels (OpenCV's ``findContours``), so they lie half a pixel inside its edge.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

# A boundary point is on the circle when within this many pixels of it (or this share of its
# radius, if larger): the ball's silhouette is an ellipse off the optical axis, its axes
# within about 5 % of each other on the stand-ins' cameras (a 0.03 m ball 0.17 m off the axis
# of a camera 0.5-0.6 m up: 1 / cos 17 deg = 1.05), +-0.7 px at a 28 px radius, plus a pixel
# grid's +-0.5 px. Chosen from those figures.
ON_CIRCLE_PX = 1.5
ON_CIRCLE_SHARE = 0.06
FIT_ITERATIONS = 8  # refits on the points on the circle (the set settled in 2-4 on the sweeps)


@dataclass(frozen=True)
class OutlineFit:
    """The circle that a blob's outline follows.

    Attributes:
        centre: (u, v) of the circle's centre, raw pixels.
        radius: its radius, pixels (to the blob's edge: the boundary points' radius + 0.5).
        on_circle: share of the outline's points within ``ON_CIRCLE_PX`` of it (0..1).
        rms_px: root mean square distance of those points from it, pixels.
        arc_deg: how much of the circle those points go round, degrees (360 less the widest
            gap between them, seen from the centre).
        fill: share of the circle's disc covered by the blob (0..1).
        outside: the blob's pixels more than ``ON_CIRCLE_PX`` outside the circle, as a share
            of the circle's area.
    """

    centre: tuple[float, float]
    radius: float
    on_circle: float
    rms_px: float
    arc_deg: float
    fill: float
    outside: float


def kasa_circle(points: np.ndarray) -> tuple[np.ndarray, float]:
    """The least-squares circle of points (n, 2), n >= 3, by Kasa's algebraic fit: centre
    (2,) and radius, pixels."""
    x, y = points[:, 0], points[:, 1]
    a = np.column_stack([x, y, np.ones(len(x))])
    b = x * x + y * y
    (p, q, s), *_ = np.linalg.lstsq(a, b, rcond=None)
    centre = np.array([p / 2.0, q / 2.0])
    return centre, float(math.sqrt(max(s + centre @ centre, 0.0)))


def widest_gap_deg(angles: np.ndarray) -> float:
    """The widest gap between angles (n,) rad on the circle, degrees (360 for none)."""
    if len(angles) == 0:
        return 360.0
    a = np.sort(np.mod(angles, 2 * math.pi))
    gaps = np.diff(np.concatenate([a, [a[0] + 2 * math.pi]]))
    return float(math.degrees(gaps.max()))


def fit_outline(
    outline: np.ndarray,
    blob: np.ndarray,
    origin: tuple[int, int],
    start: tuple[float, float],
    expected_radius: float,
) -> OutlineFit | None:
    """The circle that a blob's outline follows, or None when fewer than 3 points are on any.

    Args:
        outline: the blob's boundary points, (n, 2) raw pixels.
        blob: the blob's pixels in its bounding box, (h, w) bool.
        origin: (u, v) of the box's top-left pixel.
        start: where the search starts, (u, v) raw pixels (the blob's centroid).
        expected_radius: the ball's apparent radius there, pixels: the first circle's, so that
            points far off a ball's size are left out from the start.
    """
    pts = np.asarray(outline, np.float64).reshape(-1, 2)
    centre, radius = np.asarray(start, np.float64), expected_radius - 0.5
    on = np.zeros(len(pts), bool)
    for i in range(FIT_ITERATIONS):
        # first pass: a quarter of the radius around the expected circle; then the tolerance
        tol = 0.25 * radius if i == 0 else max(ON_CIRCLE_PX, ON_CIRCLE_SHARE * radius)
        new = np.abs(np.linalg.norm(pts - centre, axis=1) - radius) <= tol
        if new.sum() < 3:
            return None
        if i > 0 and np.array_equal(new, on):
            break
        on = new
        centre, radius = kasa_circle(pts[on])
    tol = max(ON_CIRCLE_PX, ON_CIRCLE_SHARE * radius)
    d = np.linalg.norm(pts - centre, axis=1) - radius
    on = np.abs(d) <= tol
    if on.sum() < 3:
        return None
    rel = pts[on] - centre
    arc = 360.0 - widest_gap_deg(np.arctan2(rel[:, 1], rel[:, 0]))
    edge = radius + 0.5
    rows, cols = np.nonzero(blob)
    dist = np.hypot(cols + origin[0] - centre[0], rows + origin[1] - centre[1])
    disc = math.pi * edge**2
    return OutlineFit(
        centre=(float(centre[0]), float(centre[1])),
        radius=float(edge),
        on_circle=float(on.mean()),
        rms_px=float(np.sqrt(np.mean(d[on] ** 2))),
        arc_deg=float(arc),
        fill=float(min(np.sum(dist <= edge) / disc, 1.0)),
        outside=float(np.sum(dist > edge + tol) / disc),
    )
