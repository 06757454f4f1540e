"""A plain printed chessboard as a calibration target (``--board chessboard``), beside the
ChArUco board of ``calibration.charuco``: the same views, the same solver and quality gates.

``squares`` counts squares, as for the ChArUco board; OpenCV names a chessboard by its inner
corners, one fewer each way: OpenCV's "9x6" chessboard (9 x 6 inner corners) is
``--squares 10 7``. The whole board must be in view (a chessboard has no markers that name its
corners). Corners are found by ``cv2.findChessboardCornersSB`` (sub-pixel accurate by design,
OpenCV 4+), ordered row by row; inner corner (i, j) lies at ((i + 1) s, (j + 1) s, 0) on the
board, origin at its top-left outer corner, as the ChArUco board's points.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from calibration.charuco import MIN_CORNERS, BoardView


@dataclass(frozen=True)
class ChessboardSpec:
    """A plain chessboard.

    Attributes:
        squares: (columns, rows) of squares (at least 3 x 3: 2 x 2 inner corners).
        square_m: side of a square, metres (measure the print).
    """

    squares: tuple[int, int] = (7, 5)
    square_m: float = 0.030
    kind = "chessboard"

    def __post_init__(self) -> None:
        from calibration.store import CalibrationError

        cols, rows = self.squares
        if cols < 3 or rows < 3 or (cols - 1) * (rows - 1) < MIN_CORNERS:
            raise CalibrationError(
                f"a chessboard of {cols} x {rows} squares has too few inner corners "
                f"(need >= {MIN_CORNERS})"
            )
        if not self.square_m > 0:
            raise CalibrationError(f"--square-m must be > 0, got {self.square_m}")

    @property
    def inner_corners(self) -> tuple[int, int]:
        """(columns, rows) of inner corners: OpenCV's pattern size."""
        return self.squares[0] - 1, self.squares[1] - 1

    @property
    def size_m(self) -> tuple[float, float]:
        """(width, height) of the squares, metres."""
        return self.squares[0] * self.square_m, self.squares[1] * self.square_m

    def describe(self) -> str:
        """Which board this is, and how to print one (for messages)."""
        c, r = self.squares
        ic, ir = self.inner_corners
        return (
            f"a plain chessboard of {c} x {r} squares ({ic} x {ir} inner corners: OpenCV's "
            f"'{ic}x{ir}' board) of {self.square_m * 1000:g} mm, all of it in view; print one "
            f"with: ergo calibrate camera --board chessboard --squares {c} {r} "
            f"--square-m {self.square_m:g} --print-board board.png"
        )

    def image(self, px_per_m: float, margin_px: int = 0) -> np.ndarray:
        """The board as a grey image (H, W) uint8 at ``px_per_m`` (top-left square black),
        with a white margin."""
        cols, rows = self.squares
        side = self.square_m * px_per_m
        h, w = round(rows * side), round(cols * side)
        yy, xx = np.mgrid[0:h, 0:w]
        black = ((np.floor(xx / side) + np.floor(yy / side)) % 2) == 0
        board = np.where(black, 0, 255).astype(np.uint8)
        return np.pad(board, margin_px, constant_values=255)

    def detect(self, image: np.ndarray, name: str = "") -> BoardView | None:
        """The board's inner corners in one image (grey or BGR), or None when not all found."""
        import cv2

        grey = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
        found, corners = cv2.findChessboardCornersSB(grey, self.inner_corners)
        if not found or corners is None:
            return None
        ic, ir = self.inner_corners
        i, j = np.meshgrid(np.arange(ic), np.arange(ir))  # row by row, as OpenCV orders them
        obj = np.column_stack(
            [(i.ravel() + 1) * self.square_m, (j.ravel() + 1) * self.square_m, np.zeros(ic * ir)]
        )
        return BoardView(obj, np.asarray(corners, np.float64).reshape(-1, 2), name)

    def to_dict(self) -> dict[str, Any]:
        return {"kind": self.kind, "squares": list(self.squares), "square_m": self.square_m}
