"""The camera file's format (``<root>/<rig_id>/camera.json``, ``ergo calibrate camera``): what a
camera calibration holds (``Intrinsics``: the camera matrix, the distortion, the image size, the
errors and uncertainties it was judged by, advice on the views) and the checks of a payload read
or about to be written (``check_camera_payload``, used by ``calibration.store``). How the
intrinsics are fitted is ``calibration.charuco``'s; the file's envelope (schema, kind, version,
rig id) is ``robot.calibration_files``'s.

Units: pixels; the distortion coefficients are OpenCV's (k1, k2, p1, p2, k3).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from plumbing.fields import Fields, is_matrix

INTRINSIC_NAMES = ("fx", "fy", "cx", "cy")
# The views are left out in at most this many groups for the held-out spread (the standard
# deviations' jackknife, ``calibration.charuco.held_out``): it decides the t quantile.
HELD_OUT_FOLDS = 15


def interval_factor(n_views: int) -> float:
    """The multiple of a standard deviation that makes a 95 % interval: Student's t with one
    fewer degrees of freedom than the jackknife's groups (``min(HELD_OUT_FOLDS, n_views)``:
    2.14 at 15 views, 2.78 at 5), the larger of the two spreads being at most that well known.
    """
    from scipy import stats

    groups = max(2, min(HELD_OUT_FOLDS, int(n_views)))
    return float(stats.t.ppf(0.975, groups - 1))


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
        std_px: standard deviation of fx, fy, cx, cy, pixels (the larger of OpenCV's estimate
            and the held-out spread).
        held_out_rms_px: RMS reprojection error of the views held out (each with the
            intrinsics fitted without it), pixels.
        held_out_per_view_px: shape (n_views,), pixels.
        advice: what views to add, in words (coverage, tilt, number), one item each.
    """

    camera_matrix: np.ndarray
    dist_coeffs: np.ndarray
    image_size: tuple[int, int]
    rms_px: float
    per_view_rms_px: np.ndarray
    n_views: int
    view_names: list[str] = field(default_factory=list)
    std_px: dict[str, float] = field(default_factory=dict)
    held_out_rms_px: float = float("nan")
    held_out_per_view_px: np.ndarray = field(default_factory=lambda: np.zeros(0))
    advice: list[str] = field(default_factory=list)

    def values(self) -> dict[str, float]:
        """fx, fy, cx, cy, pixels."""
        k = self.camera_matrix
        v = (k[0, 0], k[1, 1], k[0, 2], k[1, 2])
        return {n: float(x) for n, x in zip(INTRINSIC_NAMES, v, strict=True)}

    def intervals_95(self) -> dict[str, tuple[float, float]]:
        """95 % intervals of fx, fy, cx, cy, pixels: each value +- ``interval_factor`` sd
        (none without standard deviations)."""
        q = interval_factor(self.n_views)
        return {
            n: (v - q * self.std_px[n], v + q * self.std_px[n])
            for n, v in self.values().items()
            if n in self.std_px
        }

    def describe(self) -> str:
        """The intrinsics with their standard deviations and the errors, one line."""
        sd = self.std_px
        parts = [
            f"{n} {v:.1f} +-{sd[n]:.1f}" if n in sd else f"{n} {v:.1f}"
            for n, v in self.values().items()
        ]
        iv = self.intervals_95()
        within = (
            "; 95 %: " + ", ".join(f"{n} {lo:.1f}-{hi:.1f}" for n, (lo, hi) in iv.items())
            if iv
            else ""
        )
        return (
            f"{', '.join(parts)} px (1 sd){within}; RMS reprojection error {self.rms_px:.3f} px "
            f"over {self.n_views} views, {self.held_out_rms_px:.3f} px on views held out"
        )

    def to_dict(self, board: Any = None) -> dict[str, Any]:
        """The payload of ``camera.json`` (``board``: the board spec the views showed, a
        ``calibration.charuco.BoardSpec`` or ``calibration.chessboard.ChessboardSpec``, kept
        in the file when given)."""
        d: dict[str, Any] = {
            "camera_matrix": self.camera_matrix.tolist(),
            "dist_coeffs": self.dist_coeffs.reshape(-1).tolist(),
            "image_size": list(self.image_size),
            "rms_px": float(self.rms_px),
            "n_views": int(self.n_views),
            "per_view_rms_px": [float(x) for x in self.per_view_rms_px],
        }
        if self.std_px:
            d["std_px"] = {k: float(v) for k, v in self.std_px.items()}
            d["intervals_95"] = {k: list(v) for k, v in self.intervals_95().items()}
        if math.isfinite(self.held_out_rms_px):
            d["held_out_rms_px"] = float(self.held_out_rms_px)
        if self.advice:
            d["advice"] = list(self.advice)
        if board is not None:
            d["board"] = board.to_dict()
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Intrinsics:
        """The intrinsics of a ``camera.json`` payload (checked by ``check_camera_payload``)."""
        return cls(
            camera_matrix=np.asarray(d["camera_matrix"], np.float64),
            dist_coeffs=np.asarray(d["dist_coeffs"], np.float64),
            image_size=(int(d["image_size"][0]), int(d["image_size"][1])),
            rms_px=float(d.get("rms_px", float("nan"))),
            per_view_rms_px=np.asarray(d.get("per_view_rms_px", []), np.float64),
            n_views=int(d.get("n_views", 0)),
            std_px={k: float(v) for k, v in (d.get("std_px") or {}).items()},
            held_out_rms_px=float(d.get("held_out_rms_px", float("nan"))),
            advice=list(d.get("advice") or []),
        )


def check_camera_payload(c: Fields) -> None:
    """The checks of a ``camera.json`` payload (``calibration.store.validate``): one-line
    errors naming the field, raised as ``c``'s error class."""
    c.matrix("camera_matrix", (3, 3))
    k = c.data["camera_matrix"]
    if not (k[0][0] > 0 and k[1][1] > 0 and k[2] == [0, 0, 1]):
        c.fail("camera_matrix", "must have positive focal lengths and last row [0, 0, 1]")
    c.matrix("dist_coeffs", (-1,))
    if len(c.data["dist_coeffs"]) not in (4, 5, 8, 12, 14):
        c.fail("dist_coeffs", "must have 4, 5, 8, 12 or 14 values")
    c.matrix("image_size", (2,))
    if any(int(s) != s or s <= 0 for s in c.data["image_size"]):
        c.fail("image_size", "must be two positive integers (width, height)")
    c.number("rms_px", 0.0, 100.0)
    c.number("n_views", 1, 10_000)
    sd = c.get("std_px", optional=True)
    if sd is not None and not (
        isinstance(sd, dict) and all(is_matrix(v, ()) and v >= 0 for v in sd.values())
    ):
        c.fail("std_px", "must map fx, fy, cx, cy to finite standard deviations >= 0, px")
    c.number("held_out_rms_px", 0.0, 1e4, optional=True)
