"""Camera intrinsics from ChArUco board views (OpenCV 5: ``CharucoBoard``,
``CharucoDetector.detectBoard``, ``board.matchImagePoints``, ``calibrateCamera``), or from a
plain chessboard's (``calibration.chessboard``): a board spec has ``detect``, ``image``,
``describe`` and ``to_dict``; the views, the solver and its gates are the same.

Quality gates (before and after solving) refuse a calibration that would be poorly
conditioned, with a one-line reason:
- at least ``MIN_VIEWS`` views in which the board was found with at least ``MIN_CORNERS``
  corners;
- the detected corners cover enough of the image (a 4x4 grid of cells);
- the board is seen at several tilts (a fronto-parallel set leaves the focal length unknown).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from calibration.store import CalibrationError

MIN_VIEWS = 8  # the floor; OpenCV's tutorial: 10-15 (docs/facts.md)
MIN_CORNERS = 6  # per view; fewer constrain a homography poorly (guess; >= 4 is the minimum)
COVERAGE_GRID = 4  # the image is split into GRID x GRID cells for the coverage check
MIN_COVERED_CELLS = 10  # of 16 (guess: the corners and edges must be seen, not only the middle)
MIN_TILTED_VIEWS = 3  # views whose board normal is at least MIN_TILT_DEG off the optical axis
MIN_TILT_DEG = 10.0  # guess
MAX_RMS_PX = 1.0  # above this the result is refused (good: < 0.5 px, OpenCV's tutorial)


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


@dataclass
class Intrinsics:
    """The result of a camera calibration.

    Attributes:
        camera_matrix: shape (3, 3), pixels.
        dist_coeffs: (k1, k2, p1, p2, k3), shape (5,).
        image_size: (width, height), pixels.
        rms_px: RMS reprojection error over all corners, pixels.
        per_view_rms_px: shape (n_views,), pixels.
        n_views: views used.
        view_names: their names, in order.
    """

    camera_matrix: np.ndarray
    dist_coeffs: np.ndarray
    image_size: tuple[int, int]
    rms_px: float
    per_view_rms_px: np.ndarray
    n_views: int
    view_names: list[str] = field(default_factory=list)

    def to_dict(self, board: BoardSpec | None = None) -> dict[str, Any]:
        d: dict[str, Any] = {
            "camera_matrix": self.camera_matrix.tolist(),
            "dist_coeffs": self.dist_coeffs.reshape(-1).tolist(),
            "image_size": list(self.image_size),
            "rms_px": float(self.rms_px),
            "n_views": int(self.n_views),
            "per_view_rms_px": [float(x) for x in self.per_view_rms_px],
        }
        if board is not None:
            d["board"] = board.to_dict()
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Intrinsics:
        return cls(
            camera_matrix=np.asarray(d["camera_matrix"], np.float64),
            dist_coeffs=np.asarray(d["dist_coeffs"], np.float64),
            image_size=(int(d["image_size"][0]), int(d["image_size"][1])),
            rms_px=float(d.get("rms_px", float("nan"))),
            per_view_rms_px=np.asarray(d.get("per_view_rms_px", []), np.float64),
            n_views=int(d.get("n_views", 0)),
        )


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


def coverage_cells(views: list[BoardView], image_size: tuple[int, int]) -> int:
    """How many of the GRID x GRID image cells contain at least one detected corner."""
    w, h = image_size
    seen = np.zeros((COVERAGE_GRID, COVERAGE_GRID), bool)
    for v in views:
        cols = np.clip((v.image_points[:, 0] / w * COVERAGE_GRID).astype(int), 0, COVERAGE_GRID - 1)
        rows = np.clip((v.image_points[:, 1] / h * COVERAGE_GRID).astype(int), 0, COVERAGE_GRID - 1)
        seen[rows, cols] = True
    return int(seen.sum())


def calibrate(
    views: list[BoardView], image_size: tuple[int, int], fit_k3: bool = False, board: Any = None
) -> Intrinsics:
    """Solve for the intrinsics; refuses too few or poorly spread views.

    Args:
        views: detected views (from a board spec's ``detect``).
        image_size: (width, height), pixels.
        board: the board looked for (its ``describe()`` goes into the too-few-views message).
        fit_k3: also fit the sixth-order radial term k3. Off by default: for webcam lenses it
            trades off against k2 and extrapolates badly towards the image corners unless the
            views cover them well (seen on synthetic views: up to 5 px at the corners).

    Raises:
        CalibrationError: a one-line reason (too few views, poor coverage, no tilt, high RMS).
    """
    import cv2

    if len(views) < MIN_VIEWS:
        looked = f"; looked for {board.describe()}" if board is not None else ""
        raise CalibrationError(
            f"only {len(views)} usable board views (need >= {MIN_VIEWS}, 10-15 is better): "
            f"show the whole board at several places and tilts{looked}"
        )
    cells = coverage_cells(views, image_size)
    if cells < MIN_COVERED_CELLS:
        raise CalibrationError(
            f"the board's corners cover only {cells} of {COVERAGE_GRID**2} image cells "
            f"(need >= {MIN_COVERED_CELLS}): move it into the corners and edges of the image"
        )
    obj = [v.object_points.astype(np.float32).reshape(-1, 1, 3) for v in views]
    img = [v.image_points.astype(np.float32).reshape(-1, 1, 2) for v in views]
    flags = 0 if fit_k3 else cv2.CALIB_FIX_K3
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12)
    rms, k, dist, rvecs, tvecs = cv2.calibrateCamera(
        obj, img, image_size, None, None, flags=flags, criteria=criteria
    )
    tilts = []
    per_view = []
    for o, i, rv, tv in zip(obj, img, rvecs, tvecs, strict=True):
        r, _ = cv2.Rodrigues(rv)
        tilts.append(np.degrees(np.arccos(min(1.0, abs(r[2, 2])))))
        proj, _ = cv2.projectPoints(o, rv, tv, k, dist)
        per_view.append(float(np.sqrt(np.mean(np.sum((proj - i) ** 2, axis=-1)))))
    n_tilted = int(np.sum(np.asarray(tilts) >= MIN_TILT_DEG))
    if n_tilted < MIN_TILTED_VIEWS:
        raise CalibrationError(
            f"only {n_tilted} views show the board tilted by >= {MIN_TILT_DEG:g} deg "
            f"(need >= {MIN_TILTED_VIEWS}): tilt it towards and away from the camera"
        )
    if rms > MAX_RMS_PX:
        worst = int(np.argmax(per_view))
        raise CalibrationError(
            f"RMS reprojection error {rms:.2f} px > {MAX_RMS_PX} px (worst view "
            f"{views[worst].name or worst}: {per_view[worst]:.2f} px): blurred or bent board?"
        )
    return Intrinsics(
        camera_matrix=k,
        dist_coeffs=np.asarray(dist, np.float64).reshape(-1)[:5],
        image_size=(int(image_size[0]), int(image_size[1])),
        rms_px=float(rms),
        per_view_rms_px=np.asarray(per_view),
        n_views=len(views),
        view_names=[v.name for v in views],
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
