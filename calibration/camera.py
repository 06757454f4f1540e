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

    def describe(self) -> str:
        """The intrinsics with their standard deviations and the errors, one line."""
        k, sd = self.camera_matrix, self.std_px
        values = dict(zip(INTRINSIC_NAMES, (k[0, 0], k[1, 1], k[0, 2], k[1, 2]), strict=True))
        parts = [
            f"{n} {v:.1f} +-{sd[n]:.1f}" if n in sd else f"{n} {v:.1f}" for n, v in values.items()
        ]
        return (
            f"{', '.join(parts)} px (1 sd); RMS reprojection error {self.rms_px:.3f} px over "
            f"{self.n_views} views, {self.held_out_rms_px:.3f} px on views held out"
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
