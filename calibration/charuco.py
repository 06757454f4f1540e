"""Camera intrinsics from ChArUco board views (OpenCV 5: ``CharucoBoard``,
``CharucoDetector.detectBoard``, ``board.matchImagePoints``, ``calibrateCameraExtended``), or
from a plain chessboard's (``calibration.chessboard``): a board spec has ``detect``, ``image``,
``describe`` and ``to_dict``; the views and the solver are the same.

A calibration is judged by what it can say about itself, not by guessed gates on the views:
- the standard deviations of the intrinsics: OpenCV's estimate (``calibrateCameraExtended``:
  from the Jacobian and the reprojection error, which assumes independent corner errors and
  understates the spread, measured below), the jackknife spread over views held out
  (``HELD_OUT_FOLDS`` groups, each left out once) and over the board's corners left out of
  every view (``corner_spread``: an error a corner repeats in every view), combined as
  two-way clustered errors (``calibrate``);
- the RMS reprojection error, over all corners and per view;
- the reprojection error of the views held out, each solved for its pose alone with the
  intrinsics fitted without it (a model that only fits the views it saw predicts new ones
  worse).

A result is refused (one line naming what is uncertain and what views to add) only when a
focal length or the principal point is known to worse than ``MAX_SD_OF_FOCAL`` of the focal
length, or when the reprojection error, on the views or held out, passes ``MAX_RMS_PX``.
How the views cover the image and how tilted they are become advice printed with the result
(``Intrinsics.advice``). docs/calibration.md gives the thresholds' reasons and the figures.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from calibration.camera import HELD_OUT_FOLDS, INTRINSIC_NAMES, Intrinsics
from calibration.store import CalibrationError

# Fewest views: the held-out check fits the intrinsics on all views but one group, so each fit
# must keep 4 views (3 views are the fewest that fix the 4 intrinsics and 4 distortion
# terms, Zhang 2000; one more for margin). Fewer views are refused; more are judged by their
# uncertainty. OpenCV's tutorial asks for 10-15 (docs/facts.md).
MIN_VIEWS = 5
MIN_CORNERS = 6  # per view; fewer constrain a homography poorly (guess; >= 4 is the minimum)
# The corners' jackknife deals the board's corners into at most this many groups (a 9 x 6
# chessboard's 54 each alone; a fit per group: ~0.05 s each at 15 views).
CORNER_FOLDS = 60
# Held-out groups (``HELD_OUT_FOLDS``, calibration/camera.py): every view is left out once
# (leave-one-out) up to that many views, then views are dealt into that many groups (a fit per
# group: ~0.05 s each at 15 views).
# The largest standard deviation of fx, fy, cx or cy accepted, as a fraction of the focal
# length: 0.5 % (3 px at fx 610). Reason: the project asks the focal length within 1 % of
# the truth (the stand-in's check), which 0.5 % at one sd gives at two; the same fraction for
# the principal point turns a pixel's viewing direction by at most 0.29 deg at one sd (3 px
# at fx 610, the principal point's check). The arena's homography, fitted to the markers,
# absorbs most of an error of these (docs/calibration.md).
MAX_SD_OF_FOCAL = 0.005
MAX_RMS_PX = 1.0  # above this the result is refused (good: < 0.5 px, OpenCV's tutorial)
GOOD_RMS_PX = 0.5  # above this a warning (OpenCV's tutorial)
# Advice only (not refusals): what a well-spread set of views shows.
COVERAGE_GRID = 4  # the image is split into GRID x GRID cells for the coverage advice
GOOD_COVERED_CELLS = 12  # of 16: the board was seen in most of the image (guess)
GOOD_TILTED_VIEWS = 3  # views tilted by at least GOOD_TILT_DEG (guess)
GOOD_TILT_DEG = 20.0  # a tilt that makes the perspective, hence the focal length, seen (guess)
GOOD_VIEWS = 10  # OpenCV's tutorial: 10-15 views
HELD_OUT_RATIO = 1.5  # held-out RMS over the views' RMS above which views are too few (guess)


@dataclass(frozen=True)
class BoardSpec:
    """A ChArUco board.

    Attributes:
        squares: (columns, rows) of chessboard squares.
        square_m: side of a square, metres (measure the print and pass the measured value).
        marker_m: side of an ArUco marker inside a white square, metres.
        dictionary: name of a ``cv2.aruco`` predefined dictionary.

    The default is 7 x 5 squares of 30 mm (fits an A4 page with margins) with 22 mm markers
    from DICT_5X5_100: a choice, not a standard.
    """

    squares: tuple[int, int] = (7, 5)
    square_m: float = 0.030
    marker_m: float = 0.022
    dictionary: str = "DICT_5X5_100"
    kind = "charuco"

    def describe(self) -> str:
        """Which board this is, how to print one, and the other kind (for messages)."""
        c, r = self.squares
        return (
            f"a ChArUco board of {c} x {r} squares of {self.square_m * 1000:g} mm with "
            f"{self.marker_m * 1000:g} mm {self.dictionary} markers; print one with: ergo "
            f"calibrate camera --squares {c} {r} --print-board board.png (a plain chessboard "
            "instead: --board chessboard --squares COLS ROWS --square-m S)"
        )

    def detect(self, image: np.ndarray, name: str = "") -> BoardView | None:
        """The board in one image: ``detect_view``."""
        return detect_view(image, self, name)

    def board(self):
        import cv2

        dico = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))
        return cv2.aruco.CharucoBoard(self.squares, self.square_m, self.marker_m, dico)

    @property
    def size_m(self) -> tuple[float, float]:
        """(width, height) of the chessboard area, metres."""
        return self.squares[0] * self.square_m, self.squares[1] * self.square_m

    def image(self, px_per_m: float, margin_px: int = 0) -> np.ndarray:
        """The board as a grey image (H, W) uint8 at ``px_per_m``, plus a white margin."""
        w, h = self.size_m
        size = (round(w * px_per_m) + 2 * margin_px, round(h * px_per_m) + 2 * margin_px)
        return self.board().generateImage(size, marginSize=margin_px, borderBits=1)

    def to_dict(self) -> dict[str, Any]:
        return {
            "kind": self.kind,
            "squares": list(self.squares),
            "square_m": self.square_m,
            "marker_m": self.marker_m,
            "dictionary": self.dictionary,
        }


@dataclass
class BoardView:
    """Matched points of one view.

    Attributes:
        object_points: shape (N, 3), metres on the board (z = 0).
        image_points: shape (N, 2), raw pixels.
        name: where the view came from (file name or frame number).
    """

    object_points: np.ndarray
    image_points: np.ndarray
    name: str = ""


def detect_view(image: np.ndarray, spec: BoardSpec, name: str = "") -> BoardView | None:
    """Find the board in one image (grey or BGR); None if fewer than ``MIN_CORNERS`` corners."""
    import cv2

    board = spec.board()
    grey = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    detector = cv2.aruco.CharucoDetector(board)
    corners, ids, _, _ = detector.detectBoard(grey)
    if ids is None or corners is None or len(ids) < MIN_CORNERS:
        return None
    obj, img = board.matchImagePoints(corners, ids)
    if obj is None or len(obj) < MIN_CORNERS:
        return None
    return BoardView(
        np.asarray(obj, np.float64).reshape(-1, 3),
        np.asarray(img, np.float64).reshape(-1, 2),
        name,
    )


def _cells(views: list[BoardView], image_size: tuple[int, int]) -> np.ndarray:
    """Which of the GRID x GRID image cells hold at least one detected corner, (GRID, GRID)."""
    w, h = image_size
    seen = np.zeros((COVERAGE_GRID, COVERAGE_GRID), bool)
    for v in views:
        cols = np.clip((v.image_points[:, 0] / w * COVERAGE_GRID).astype(int), 0, COVERAGE_GRID - 1)
        rows = np.clip((v.image_points[:, 1] / h * COVERAGE_GRID).astype(int), 0, COVERAGE_GRID - 1)
        seen[rows, cols] = True
    return seen


def coverage_cells(views: list[BoardView], image_size: tuple[int, int]) -> int:
    """How many of the GRID x GRID image cells contain at least one detected corner."""
    return int(_cells(views, image_size).sum())


def view_advice(
    views: list[BoardView], image_size: tuple[int, int], tilts_deg: np.ndarray
) -> list[str]:
    """What views to add, in words, one item per shortfall (empty for a well-spread set):
    the image's corners and edges unseen, too few tilted views, too few views."""
    out = []
    seen = _cells(views, image_size)
    corners = int(seen[0, 0]) + int(seen[0, -1]) + int(seen[-1, 0]) + int(seen[-1, -1])
    cells = int(seen.sum())
    if corners < 4 or cells < GOOD_COVERED_CELLS:
        out.append(
            f"add views near the image corners and edges (the board covered {cells} of "
            f"{COVERAGE_GRID**2} image cells, {corners} of the 4 corners)"
        )
    tilted = int(np.sum(np.asarray(tilts_deg) >= GOOD_TILT_DEG))
    if tilted < GOOD_TILTED_VIEWS:
        out.append(
            f"add views with the board tilted by {GOOD_TILT_DEG:.0f}-45 deg towards and away "
            f"from the camera ({tilted} of {len(views)} views are)"
        )
    if len(views) < GOOD_VIEWS:
        out.append(f"add views ({len(views)} used; 10-15 is better)")
    return out


def _solve(views: list[BoardView], image_size: tuple[int, int], flags: int) -> tuple:
    """``cv2.calibrateCameraExtended`` on the views: (rms, K, dist, rvecs, tvecs, sd of the
    intrinsics (fx, fy, cx, cy, k1, ...), per-view RMS)."""
    import cv2

    obj = [v.object_points.astype(np.float32).reshape(-1, 1, 3) for v in views]
    img = [v.image_points.astype(np.float32).reshape(-1, 1, 2) for v in views]
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12)
    rms, k, dist, rvecs, tvecs, sd, _, per_view = cv2.calibrateCameraExtended(
        obj, img, image_size, None, None, flags=flags, criteria=criteria
    )
    return rms, k, dist, rvecs, tvecs, np.asarray(sd).reshape(-1), np.asarray(per_view).reshape(-1)


def _reprojection_rms(view: BoardView, k: np.ndarray, dist: np.ndarray) -> float:
    """RMS error of one view reprojected with its own pose (solved here) and these
    intrinsics, pixels."""
    import cv2

    ok, rvec, tvec = cv2.solvePnP(view.object_points, view.image_points, k, dist)
    if not ok:
        return math.inf
    proj, _ = cv2.projectPoints(view.object_points, rvec, tvec, k, dist)
    return float(np.sqrt(np.mean(np.sum((proj.reshape(-1, 2) - view.image_points) ** 2, axis=1))))


def held_out(
    views: list[BoardView], image_size: tuple[int, int], flags: int, folds: int = HELD_OUT_FOLDS
) -> tuple[np.ndarray, np.ndarray]:
    """Each group of views left out in turn (views dealt into ``min(folds, n)`` groups).

    Returns:
        (jackknife standard deviations of fx, fy, cx, cy over the fits without each group,
        shape (4,), pixels; each view's reprojection RMS with the intrinsics fitted without
        it, shape (n,), pixels). A fit that fails counts as an infinite spread.
    """
    import cv2

    n = len(views)
    groups = min(folds, n)
    estimates = []
    errors = np.full(n, math.inf)
    for g in range(groups):
        out = [i for i in range(n) if i % groups == g]
        kept = [v for i, v in enumerate(views) if i % groups != g]
        try:
            _, k, dist, *_ = _solve(kept, image_size, flags)
        except cv2.error:
            return np.full(4, math.inf), errors
        estimates.append([k[0, 0], k[1, 1], k[0, 2], k[1, 2]])
        for i in out:
            errors[i] = _reprojection_rms(views[i], k, dist)
    est = np.asarray(estimates)
    spread = np.sqrt((groups - 1) / groups * np.sum((est - est.mean(axis=0)) ** 2, axis=0))
    return spread, errors


def corner_spread(
    views: list[BoardView], image_size: tuple[int, int], flags: int, folds: int = CORNER_FOLDS
) -> np.ndarray:
    """The jackknife over the board's corners: each corner of the board (dealt into at most
    ``folds`` groups) left out of every view in turn; the standard deviations of fx, fy, cx,
    cy over those fits, shape (4,), pixels (infinite if a fit fails).

    Why: a corner's detection error repeats in every view that shows it (the print, the
    lens's blur and the sensor around that corner; on the stand-ins the rendering of its
    texture), and the views' jackknife, which takes the views as independent, cannot see an
    error they share. Measured on stand-in 215's views (in process): the detected corners
    0.01-0.09 px off the hidden camera's projection on average, cx 0.70 px off where the views'
    jackknife said +-0.17 px and this one +-0.46 px; the exact projections give cx exactly.
    """
    import cv2

    keys = sorted({tuple(np.round(p, 6)) for v in views for p in v.object_points})
    groups = min(folds, len(keys))
    group_of = {k: i % groups for i, k in enumerate(keys)}
    estimates = []
    for g in range(groups):
        kept = []
        for v in views:
            keep = np.array([group_of[tuple(np.round(p, 6))] != g for p in v.object_points])
            if keep.sum() >= MIN_CORNERS:
                kept.append(BoardView(v.object_points[keep], v.image_points[keep], v.name))
        try:
            _, k, *_ = _solve(kept, image_size, flags)
        except cv2.error:
            return np.full(4, math.inf)
        estimates.append([k[0, 0], k[1, 1], k[0, 2], k[1, 2]])
    est = np.asarray(estimates)
    return np.sqrt((groups - 1) / groups * np.sum((est - est.mean(axis=0)) ** 2, axis=0))


def calibrate(
    views: list[BoardView], image_size: tuple[int, int], fit_k3: bool = False, board: Any = None
) -> Intrinsics:
    """Solve for the intrinsics and judge them by their uncertainty (module docstring).

    Args:
        views: detected views (from a board spec's ``detect``).
        image_size: (width, height), pixels.
        board: the board looked for (its ``describe()`` goes into the too-few-views message).
        fit_k3: also fit the sixth-order radial term k3. Off by default: for webcam lenses it
            trades off against k2 and extrapolates badly towards the image corners unless the
            views cover them well (seen on synthetic views: up to 5 px at the corners).

    Raises:
        CalibrationError: a one-line reason: too few views; a focal length or the principal
            point too uncertain (with the views to add); a reprojection error too high.
    """
    import cv2

    if len(views) < MIN_VIEWS:
        looked = f"; looked for {board.describe()}" if board is not None else ""
        raise CalibrationError(
            f"only {len(views)} usable board views (need >= {MIN_VIEWS}, 10-15 is better): "
            f"show the whole board at several places and tilts{looked}"
        )
    flags = 0 if fit_k3 else cv2.CALIB_FIX_K3
    try:
        rms, k, dist, rvecs, _, sd_cv, per_view = _solve(views, image_size, flags)
    except cv2.error as exc:
        raise CalibrationError(
            f"the solver failed on these {len(views)} views ({str(exc).strip().splitlines()[-1]})"
            ": show the board at several places and tilts"
        ) from None
    tilts = np.array(
        [np.degrees(np.arccos(min(1.0, abs(cv2.Rodrigues(rv)[0][2, 2])))) for rv in rvecs]
    )
    spread, errors = held_out(views, image_size, flags)
    shared = corner_spread(views, image_size, flags)
    # views and corners both clustered (Cameron, Gelbach & Miller, J. Bus. Econ. Stat. 29, 238
    # (2011)): the two jackknifes' variances less OpenCV's (independent corners), at least each
    var_cv, var_views, var_corners = sd_cv[:4] ** 2, spread**2, shared**2
    sd = np.sqrt(np.maximum.reduce([var_views + var_corners - var_cv, var_views, var_corners]))
    sd = np.maximum(sd, sd_cv[:4])
    advice = view_advice(views, image_size, tilts)
    std_px = {name: float(v) for name, v in zip(INTRINSIC_NAMES, sd, strict=True)}
    focal = float(min(k[0, 0], k[1, 1]))
    worst = max(INTRINSIC_NAMES, key=lambda name: std_px[name])
    if not std_px[worst] <= MAX_SD_OF_FOCAL * focal:
        add = "; ".join(advice) if advice else "add views at other places, distances and tilts"
        known = f"+-{std_px[worst]:.1f} px" if math.isfinite(std_px[worst]) else "not at all"
        raise CalibrationError(
            f"{worst} known to {known} ({std_px[worst] / focal:.1%} of the focal length; "
            f"need <= {MAX_SD_OF_FOCAL:.1%}): {add}"
        )
    if rms > MAX_RMS_PX:
        w = int(np.argmax(per_view))
        raise CalibrationError(
            f"RMS reprojection error {rms:.2f} px > {MAX_RMS_PX} px (worst view "
            f"{views[w].name or w}: {per_view[w]:.2f} px): blurred or bent board?"
        )
    held_rms = float(np.sqrt(np.mean(errors**2)))
    if not held_rms <= MAX_RMS_PX:
        w = int(np.argmax(errors))
        raise CalibrationError(
            f"views held out are reprojected with {held_rms:.2f} px RMS (> {MAX_RMS_PX} px; worst "
            f"{views[w].name or w}: {errors[w]:.2f} px): the fit does not predict new views; "
            + ("; ".join(advice) if advice else "add views, check that the board is flat")
        )
    if held_rms > HELD_OUT_RATIO * rms:
        advice.append(
            f"add views: the views held out are reprojected {held_rms / rms:.1f} times worse "
            "than those fitted"
        )
    return Intrinsics(
        camera_matrix=k,
        dist_coeffs=np.asarray(dist, np.float64).reshape(-1)[:5],
        image_size=(int(image_size[0]), int(image_size[1])),
        rms_px=float(rms),
        per_view_rms_px=per_view,
        n_views=len(views),
        view_names=[v.name for v in views],
        std_px=std_px,
        held_out_rms_px=held_rms,
        held_out_per_view_px=errors,
        advice=advice,
    )


IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")


def views_from_folder(
    folder: str | Path, spec: Any
) -> tuple[list[BoardView], tuple[int, int], list[str]]:
    """Detect the board in every image of a folder.

    Returns:
        (views, image size (width, height), names of the images where it was not found).
    """
    import cv2

    files = sorted(p for p in Path(folder).iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
    if not files:
        raise CalibrationError(f"no images ({', '.join(IMAGE_SUFFIXES)}) in {folder}")
    views, missed = [], []
    size: tuple[int, int] | None = None
    for f in files:
        image = cv2.imread(str(f), cv2.IMREAD_GRAYSCALE)
        if image is None:
            missed.append(f.name)
            continue
        this = (image.shape[1], image.shape[0])
        if size is not None and this != size:
            raise CalibrationError(f"{f.name} is {this[0]}x{this[1]}, others {size[0]}x{size[1]}")
        size = this
        view = spec.detect(image, f.name)
        (views.append(view) if view is not None else missed.append(f.name))
    assert size is not None or not views
    return views, size or (0, 0), missed
