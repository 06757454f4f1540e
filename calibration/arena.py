"""The arena plane: a homography from camera pixels to metres on the arena floor, the camera's
position above it, the arena's centre and radius, and the ball's colour range.

Two ways to give the plane:
- four (or more) ArUco markers lying flat at known positions (``MarkerLayout``), detected in the
  undistorted frame, and those near the edge that undistortion pushed out of it in the raw
  frame, their corners undistorted; all their corners are used (16 points for 4 markers);
- four clicked points: pixel coordinates (e.g. of the arena's corners, read off a saved frame)
  and their known arena positions.

Arena coordinates: metres, origin at the arm's base, x to the image's right and y up it when
the camera looks straight down (the twin's convention). A marker is laid so that its top edge
(as printed) faces +y.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from calibration.store import CalibrationError
from sim.models.make_scene import ARENA_RADIUS
from vision.rectify import (
    ArenaModel,
    apply_homography,
    estimate_camera_position,
    fit_homography,
    pixels_to_arena,
    undistort_image,
    undistort_points,
)
from vision.tracker import HSVRange

# The twin's layout (and a suggestion for the rig): 30 mm DICT_4X4_50 markers 0..3 on the
# floor's corners outside the wall (wall inner radius 0.20 m, sim/models/make_scene.py), where
# the 0.55 m high 45-degree camera still sees them. A choice, not a standard.
DEFAULT_MARKERS: dict[int, tuple[float, float]] = {
    0: (-0.19, 0.19),
    1: (0.19, 0.19),
    2: (0.19, -0.19),
    3: (-0.19, -0.19),
}
DEFAULT_MARKER_SIZE_M = 0.03
DEFAULT_RADIUS_M = ARENA_RADIUS  # the twin's arena, m (sim/models/make_scene.py)
MAX_RESIDUAL_MM = 5.0  # refuse an arena whose points disagree with the fit by more (guess)


@dataclass(frozen=True)
class MarkerLayout:
    """ArUco markers lying on the arena floor.

    Attributes:
        markers: id -> centre (x, y), metres.
        size_m: side of each marker's black square, metres.
        dictionary: ``cv2.aruco`` predefined dictionary name.
    """

    markers: dict[int, tuple[float, float]] = field(default_factory=lambda: dict(DEFAULT_MARKERS))
    size_m: float = DEFAULT_MARKER_SIZE_M
    dictionary: str = "DICT_4X4_50"

    def corners(self, marker_id: int) -> np.ndarray:
        """Arena positions of a marker's corners in ArUco order (top-left, top-right,
        bottom-right, bottom-left as printed), shape (4, 2), metres."""
        x, y = self.markers[marker_id]
        h = self.size_m / 2
        return np.array([[x - h, y + h], [x + h, y + h], [x + h, y - h], [x - h, y - h]])

    def to_dict(self) -> dict[str, Any]:
        return {
            "markers": {str(k): list(v) for k, v in self.markers.items()},
            "size_m": self.size_m,
            "dictionary": self.dictionary,
        }


def parse_markers(text: str) -> dict[int, tuple[float, float]]:
    """``"0:-0.19,0.19;1:0.19,0.19;..."`` -> {id: (x, y)} (metres)."""
    out: dict[int, tuple[float, float]] = {}
    for item in text.replace(" ", "").split(";"):
        if not item:
            continue
        try:
            key, xy = item.split(":")
            x, y = (float(v) for v in xy.split(","))
            out[int(key)] = (x, y)
        except ValueError:
            raise CalibrationError(f"bad marker {item!r}: expected ID:X,Y in metres") from None
    if len(out) < 1:
        raise CalibrationError("no markers given")
    return out


def detect_markers(
    image: np.ndarray, layout: MarkerLayout, camera_matrix: np.ndarray, dist_coeffs: np.ndarray
) -> dict[int, np.ndarray]:
    """Find the layout's markers in a raw frame.

    The markers are looked for in the undistorted frame first (sub-pixel refinement works best
    on straight edges: corners within 0.2-0.3 px of the truth on the twin, against 0.3-0.8 px
    refined in the raw frame, measured), then, those not found there, in the raw frame, their
    corners undistorted (``undistort_points``): undistorting the whole frame pushes what lies
    near the edges of a barrel-distorted view out of it (a marker 21 cm off the arm's base in
    each direction, seen from the twin's 0.55 m with k1 = -0.25: measured, tests/calibration).

    Returns:
        id -> corners, shape (4, 2), undistorted pixels of the same camera matrix, for each
        marker of the layout that was found.
    """
    und = undistort_image(image, camera_matrix, dist_coeffs)
    found = _aruco_corners(und, layout)
    if np.any(dist_coeffs) and len(found) < len(layout.markers):
        for i, c in _aruco_corners(image, layout).items():
            found.setdefault(i, undistort_points(c, camera_matrix, dist_coeffs))
    return found


def _aruco_corners(image: np.ndarray, layout: MarkerLayout) -> dict[int, np.ndarray]:
    """id -> corners (4, 2) in ``image``'s pixels of the layout's markers found there
    (sub-pixel refined)."""
    import cv2

    grey = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    dico = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, layout.dictionary))
    params = cv2.aruco.DetectorParameters()
    params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    corners, ids, _ = cv2.aruco.ArucoDetector(dico, params).detectMarkers(grey)
    found: dict[int, np.ndarray] = {}
    if ids is None:
        return found
    for c, i in zip(corners, np.asarray(ids).reshape(-1), strict=True):
        if int(i) in layout.markers:
            found[int(i)] = np.asarray(c, np.float64).reshape(4, 2)
    return found


@dataclass
class ArenaFit:
    """An arena calibration and how well its points agree.

    Attributes:
        model: the arena model.
        residuals_mm: distance between each calibration point's known position and where the
            model maps its pixel, shape (N,), millimetres.
        points_used: N.
    """

    model: ArenaModel
    residuals_mm: np.ndarray
    points_used: int


def fit_arena(
    undistorted_px: np.ndarray,
    arena_xy: np.ndarray,
    camera_matrix: np.ndarray,
    dist_coeffs: np.ndarray,
    image_size: tuple[int, int],
    centre: tuple[float, float] = (0.0, 0.0),
    radius: float = DEFAULT_RADIUS_M,
    with_camera_position: bool = True,
) -> ArenaFit:
    """Fit the arena model to point pairs.

    Args:
        undistorted_px: shape (N, 2), undistorted pixels (N >= 4, not collinear).
        arena_xy: shape (N, 2), metres on the floor.
        camera_matrix: (3, 3); dist_coeffs: (k,): the camera's intrinsics.
        image_size: (width, height), pixels.
        centre: arena centre (x, y), metres; radius: metres.
        with_camera_position: solve for the camera's position (needs trustworthy intrinsics;
            without it, points above the floor cannot be corrected for parallax).
    """
    px = np.asarray(undistorted_px, np.float64).reshape(-1, 2)
    xy = np.asarray(arena_xy, np.float64).reshape(-1, 2)
    if len(px) < 4:
        raise CalibrationError(f"need >= 4 points on the arena plane, got {len(px)}")
    try:
        h = fit_homography(px, xy)
    except ValueError as exc:
        raise CalibrationError(str(exc)) from None
    position = None
    if with_camera_position:
        try:
            position = estimate_camera_position(px, xy, camera_matrix, np.zeros(5))
        except ValueError as exc:
            raise CalibrationError(str(exc)) from None
    model = ArenaModel(
        camera_matrix=camera_matrix,
        dist_coeffs=dist_coeffs,
        image_size=image_size,
        homography=h,
        centre=np.asarray(centre, np.float64),
        radius=radius,
        camera_position=position,
    )
    residuals = np.linalg.norm(apply_homography(h, px) - xy, axis=1) * 1000.0
    return ArenaFit(model, residuals, len(px))


def arena_from_markers(
    image: np.ndarray,
    layout: MarkerLayout,
    camera_matrix: np.ndarray,
    dist_coeffs: np.ndarray,
    centre: tuple[float, float] = (0.0, 0.0),
    radius: float = DEFAULT_RADIUS_M,
    min_markers: int = 4,
) -> ArenaFit:
    """Arena calibration from a frame showing the layout's markers.

    Raises:
        CalibrationError: fewer than ``min_markers`` markers found, or residuals above
            ``MAX_RESIDUAL_MM``.
    """
    found = detect_markers(image, layout, camera_matrix, dist_coeffs)
    if len(found) < min_markers:
        missing = sorted(set(layout.markers) - set(found))
        raise CalibrationError(
            f"found {len(found)} of the arena markers (need >= {min_markers}); missing ids "
            f"{missing}: check lighting, the dictionary ({layout.dictionary}) and that they "
            "are in view"
        )
    ids = sorted(found)
    px = np.concatenate([found[i] for i in ids])
    xy = np.concatenate([layout.corners(i) for i in ids])
    size = (image.shape[1], image.shape[0])
    fit = fit_arena(px, xy, camera_matrix, dist_coeffs, size, centre, radius)
    _check_residuals(fit)
    return fit


def arena_from_points(
    raw_px: np.ndarray,
    arena_xy: np.ndarray,
    camera_matrix: np.ndarray,
    dist_coeffs: np.ndarray,
    image_size: tuple[int, int],
    centre: tuple[float, float] = (0.0, 0.0),
    radius: float = DEFAULT_RADIUS_M,
) -> ArenaFit:
    """Arena calibration from clicked points: raw pixels (N, 2) and their arena positions
    (N, 2) in metres (N >= 4)."""
    und = undistort_points(np.asarray(raw_px, np.float64), camera_matrix, dist_coeffs)
    fit = fit_arena(und, arena_xy, camera_matrix, dist_coeffs, image_size, centre, radius)
    if len(und) > 4:
        _check_residuals(fit)
    return fit


def _check_residuals(fit: ArenaFit) -> None:
    worst = float(fit.residuals_mm.max())
    if worst > MAX_RESIDUAL_MM:
        raise CalibrationError(
            f"arena points disagree with the plane fit by up to {worst:.1f} mm "
            f"(> {MAX_RESIDUAL_MM} mm): a marker moved, is not flat, or its position is wrong"
        )


# ---- a sheet of the markers to print -------------------------------------------------------
A4_MM = (210.0, 297.0)  # paper (width, height), mm (ISO 216)
MM_PER_INCH = 25.4


def marker_sheet(
    layout: MarkerLayout,
    dpi: float = 300.0,
    radius_m: float = DEFAULT_RADIUS_M,
    paper_mm: tuple[float, float] = A4_MM,
) -> np.ndarray:
    """An A4 page (grey, (H, W) uint8 at ``dpi``) holding the layout's markers to cut out, each
    at its printed size with a one-cell white quiet zone and a cutting frame, labelled with its
    id and where its centre goes, a map of the arena (seen from the camera: x to the right, y
    up) showing where each marker lies and which way its top edge faces, and a 50 mm scale bar
    to check that the page was printed at 100 %.

    Raises:
        CalibrationError: the markers do not fit on one page at that size.
    """
    import cv2

    px_mm = dpi / MM_PER_INCH
    w, h = round(paper_mm[0] * px_mm), round(paper_mm[1] * px_mm)
    page = np.full((h, w), 255, np.uint8)
    dico = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, layout.dictionary))
    side = round(layout.size_m * 1000 * px_mm)
    ids = sorted(layout.markers)
    cols = 2
    cell_w = w // cols
    cell_h = round(side * 1.5 + 24 * px_mm)
    rows = -(-len(ids) // cols)
    top = round(30 * px_mm)
    if side * 1.4 > cell_w or top + rows * cell_h > h * 0.6:
        raise CalibrationError(
            f"{len(ids)} markers of {layout.size_m * 1000:g} mm do not fit on one page: print "
            "fewer or smaller markers (--markers, --marker-size)"
        )
    font, thick = cv2.FONT_HERSHEY_SIMPLEX, max(1, round(px_mm * 0.3))
    scale = px_mm * 0.12

    def text(s: str, x: int, y: int, size: float = 1.0) -> None:
        cv2.putText(page, s, (x, y), font, scale * size, 0, thick, cv2.LINE_AA)

    text(
        f"arena markers: {layout.dictionary}, black square {layout.size_m * 1000:g} mm; "
        "print at 100 %, cut out, lay flat, top edge (arrow) towards +y",
        round(8 * px_mm), round(12 * px_mm), 0.8,
    )  # fmt: skip
    for n, marker_id in enumerate(ids):
        cx = (n % cols) * cell_w + cell_w // 2
        cy = top + (n // cols) * cell_h + side // 2 + round(4 * px_mm)
        x0, y0 = cx - side // 2, cy - side // 2
        page[y0 : y0 + side, x0 : x0 + side] = cv2.aruco.generateImageMarker(dico, marker_id, side)
        quiet = side // 6 + round(3 * px_mm)  # the marker's one cell (4x4 + border: 1/6) and 3 mm
        cv2.rectangle(
            page, (x0 - quiet, y0 - quiet), (x0 + side + quiet, y0 + side + quiet), 160, 1
        )
        cv2.arrowedLine(page, (cx, y0 - quiet + 2), (cx, y0 - quiet - round(5 * px_mm)), 0, thick)
        mx, my = layout.markers[marker_id]
        text(
            f"id {marker_id}: centre at x {mx * 1000:+.0f} mm, y {my * 1000:+.0f} mm",
            x0 - quiet, y0 + side + quiet + round(6 * px_mm), 0.7,
        )  # fmt: skip
    # the map: the arena from above, as the camera sees it
    span = max(radius_m, *(max(abs(x), abs(y)) + layout.size_m for x, y in layout.markers.values()))
    box = min(w * 0.8, h * 0.33)
    m_px = box / (2 * span)
    ox, oy = w // 2, round(h - box / 2 - 25 * px_mm)

    def at(x: float, y: float) -> tuple[int, int]:
        return round(ox + x * m_px), round(oy - y * m_px)

    cv2.circle(page, at(0, 0), round(radius_m * m_px), 0, thick)
    cv2.circle(page, at(0, 0), max(2, round(0.02 * m_px)), 0, -1)
    text("arm base (0, 0)", *at(0.025, -0.035), 0.7)
    cv2.arrowedLine(page, at(0, 0), at(span * 0.5, 0), 0, thick)
    cv2.arrowedLine(page, at(0, 0), at(0, span * 0.5), 0, thick)
    text("x", *at(span * 0.52, -0.01))
    text("+y (top of the camera image)", *at(0.01, span * 0.52))
    for marker_id in ids:
        mx, my = layout.markers[marker_id]
        hs = layout.size_m / 2
        cv2.rectangle(page, at(mx - hs, my + hs), at(mx + hs, my - hs), 0, -1)
        cv2.arrowedLine(page, at(mx, my + hs), at(mx, my + hs + 0.02), 0, thick)
        text(str(marker_id), *at(mx + hs + 0.005, my - hs))
    text(
        f"where they go (to scale; arena radius {radius_m * 1000:g} mm):",
        round(8 * px_mm),
        round(oy - box / 2 - 4 * px_mm),
        0.7,
    )
    bar0 = (round(8 * px_mm), h - round(10 * px_mm))
    cv2.line(page, bar0, (bar0[0] + round(50 * px_mm), bar0[1]), 0, max(2, thick))
    text("50 mm", bar0[0], bar0[1] - round(2 * px_mm), 0.7)
    return page


def arena_payload(
    fit: ArenaFit,
    ranges: list[HSVRange] | None,
    ball_radius_m: float,
    source: str,
    layout: MarkerLayout | None = None,
) -> dict[str, Any]:
    """The ``arena`` calibration file's data."""
    d = fit.model.to_dict()
    d["residual_max_mm"] = float(fit.residuals_mm.max())
    d["points_used"] = int(fit.points_used)
    d["ball_radius_m"] = float(ball_radius_m)
    d["source"] = source
    if ranges:
        d["ball_hsv_ranges"] = [r.to_list() for r in ranges]
    if layout is not None:
        d["markers"] = layout.to_dict()
    return d


def ball_position_check(
    model: ArenaModel, pixel: tuple[float, float], ball_radius_m: float
) -> np.ndarray:
    """Where the model puts a ball seen at ``pixel`` (raw), shape (2,), metres."""
    height = ball_radius_m if model.camera_position is not None else 0.0
    return pixels_to_arena(model, np.asarray(pixel, np.float64), height=height)[0]
