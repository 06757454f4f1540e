"""The calibration boards the hands hold: a ChArUco board or a plain chessboard, its geometry
given by the hands' command, its image made with OpenCV at run time.

The conventions are those of the boards a camera calibration detects (``ergo calibrate
camera``): a ChArUco board is OpenCV's ``CharucoBoard`` image (``generateImage``, one-bit marker
borders); a chessboard's top-left square is black. Board coordinates: metres from the top-left
outer corner of the squares, x along the columns (image right), y along the rows (image
down). Around the squares lies a white margin (paper; default one square), which a
chessboard's detector needs.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

KINDS = ("charuco", "chessboard")
DEFAULT_DICTIONARY = "DICT_5X5_100"  # as ``ergo calibrate camera``'s default ChArUco board
MAX_SQUARES = 40  # per side (guess: more than any printed board)
MAX_SIDE_M = 1.0  # a board larger than this is no hand-held board (guess)


class BoardError(ValueError):
    """A board's geometry that cannot be; the message is one line."""


@dataclass(frozen=True)
class BoardGeometry:
    """A calibration board.

    Attributes:
        kind: ``"charuco"`` or ``"chessboard"``.
        squares: (columns, rows) of squares.
        square_m: side of a square, metres.
        marker_m: side of a ChArUco marker, metres (None for a chessboard).
        dictionary: a ``cv2.aruco`` predefined dictionary name (ChArUco only).
        margin_m: white paper around the squares, metres.
    """

    kind: str
    squares: tuple[int, int]
    square_m: float
    marker_m: float | None = None
    dictionary: str | None = None
    margin_m: float | None = None

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> BoardGeometry:
        """From a hands command's ``board`` object; every fault is a ``BoardError``."""
        import cv2

        if not isinstance(data, Mapping):
            raise BoardError(f"board must be an object, got {type(data).__name__}")
        known = {"kind", "squares", "square_m", "marker_m", "dictionary", "margin_m"}
        unknown = sorted(set(data) - known)
        if unknown:
            raise BoardError(f"board: unknown field(s) {', '.join(unknown)}")
        kind = data.get("kind", "charuco")
        if kind not in KINDS:
            raise BoardError(f"board kind {kind!r}: expected one of {', '.join(KINDS)}")
        squares = data.get("squares")
        if (
            not isinstance(squares, list | tuple)
            or len(squares) != 2
            or not all(isinstance(s, int) and not isinstance(s, bool) for s in squares)
            or not all(2 <= s <= MAX_SQUARES for s in squares)
        ):
            raise BoardError(
                f"board squares must be two integers (columns, rows) in 2..{MAX_SQUARES}, "
                f"got {squares!r}"
            )
        square_m = _positive(data.get("square_m"), "square_m")
        margin = data.get("margin_m")
        margin_m = square_m if margin is None else _positive(margin, "margin_m", zero=True)
        marker_m = dictionary = None
        if kind == "charuco":
            marker_m = _positive(data.get("marker_m", 0.75 * square_m), "marker_m")
            if marker_m >= square_m:
                raise BoardError(
                    f"board marker_m {marker_m} must be smaller than square_m {square_m}"
                )
            dictionary = data.get("dictionary", DEFAULT_DICTIONARY)
            if not isinstance(dictionary, str) or not isinstance(
                getattr(cv2.aruco, dictionary, None), int
            ):
                raise BoardError(f"board dictionary {dictionary!r} is not a cv2.aruco dictionary")
            cells = (squares[0] * squares[1]) // 2
            size = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, dictionary)).bytesList
            if cells > size.shape[0]:
                raise BoardError(
                    f"board of {squares[0]} x {squares[1]} squares needs {cells} markers; "
                    f"{dictionary} has {size.shape[0]}"
                )
        elif "marker_m" in data or "dictionary" in data:
            raise BoardError("a chessboard has no markers: drop marker_m and dictionary")
        geometry = cls(kind, (squares[0], squares[1]), square_m, marker_m, dictionary, margin_m)
        if max(geometry.size_m) > MAX_SIDE_M:
            raise BoardError(
                f"board of {geometry.size_m[0]:.2f} x {geometry.size_m[1]:.2f} m is larger "
                f"than a hand-held board ({MAX_SIDE_M} m)"
            )
        return geometry

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {
            "kind": self.kind,
            "squares": list(self.squares),
            "square_m": self.square_m,
            "margin_m": self.margin_m,
        }
        if self.kind == "charuco":
            d["marker_m"] = self.marker_m
            d["dictionary"] = self.dictionary
        return d

    @property
    def squares_m(self) -> tuple[float, float]:
        """(width, height) of the squares, metres."""
        return self.squares[0] * self.square_m, self.squares[1] * self.square_m

    @property
    def size_m(self) -> tuple[float, float]:
        """(width, height) of the whole board, margin included, metres."""
        w, h = self.squares_m
        m = self.margin_m or 0.0
        return w + 2 * m, h + 2 * m

    def describe(self) -> str:
        c, r = self.squares
        what = "ChArUco board" if self.kind == "charuco" else "chessboard"
        return f"a {what} of {c} x {r} squares of {self.square_m * 1000:g} mm"

    def image(self, px_per_m: float) -> np.ndarray:
        """The whole board (margin included) as a grey image (H, W) uint8 at ``px_per_m``."""
        import cv2

        margin = round((self.margin_m or 0.0) * px_per_m)
        w, h = self.squares_m
        if self.kind == "charuco":
            dico = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))
            board = cv2.aruco.CharucoBoard(self.squares, self.square_m, self.marker_m, dico)
            size = (round(w * px_per_m) + 2 * margin, round(h * px_per_m) + 2 * margin)
            return board.generateImage(size, marginSize=margin, borderBits=1)
        side = self.square_m * px_per_m
        hh, ww = round(h * px_per_m), round(w * px_per_m)
        yy, xx = np.mgrid[0:hh, 0:ww]
        black = ((np.floor(xx / side) + np.floor(yy / side)) % 2) == 0
        squares = np.where(black, 0, 255).astype(np.uint8)
        return np.pad(squares, margin, constant_values=255)

    def texture(self, side_px: int) -> np.ndarray:
        """The whole board stretched over a square texture (side_px, side_px, 3) RGB uint8 (its
        long side drawn at least at ``side_px``, then area-averaged)."""
        import cv2

        w, h = self.size_m
        px_per_m = 2.0 * side_px / min(w, h)
        grey = self.image(px_per_m)
        small = cv2.resize(grey, (side_px, side_px), interpolation=cv2.INTER_AREA)
        return np.repeat(small[:, :, None], 3, axis=2)

    def object_corners(self) -> np.ndarray:
        """The inner corners of the squares in board coordinates, shape (N, 2), metres, row by
        row (OpenCV's order for both kinds)."""
        c, r = self.squares
        i, j = np.meshgrid(np.arange(1, c), np.arange(1, r))
        return np.column_stack([i.ravel(), j.ravel()]) * self.square_m


def _positive(value: Any, name: str, zero: bool = False) -> float:
    ok = isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)
    if not ok or value < 0 or (value == 0 and not zero):
        sign = ">= 0" if zero else "> 0"
        raise BoardError(f"board {name} must be a number {sign} (metres), got {value!r}")
    if value > MAX_SIDE_M:
        raise BoardError(f"board {name} {value} m is larger than a hand-held board")
    return float(value)
