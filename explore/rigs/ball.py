"""Where the ball is: the tracker on camera frames (real rigs, or the twin seen as a real rig),
or the twin's ground truth.

A ball locator maps a BGR frame (H, W, 3) uint8 to the ball's centre (x, y) on the arena,
metres, shape (2,), NaN when the tracker did not see it (hidden by the arm, ambiguous).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

BallLocator = Callable[[np.ndarray], np.ndarray]


def tracker_locator(arena: Any, tracker_config: Any = None) -> BallLocator:
    """A locator backed by ``vision.tracker.BallTracker`` with an ``ArenaModel``."""
    from vision.tracker import BallTracker

    tracker = BallTracker(tracker_config, arena)

    def locate(frame: np.ndarray) -> np.ndarray:
        obs = tracker.track(frame)
        if not obs.seen or obs.xy is None:
            return np.full(2, np.nan)
        return np.asarray(obs.xy, dtype=float)

    return locate


def twin_arena_model(camera: Any) -> Any:
    """The exact ``ArenaModel`` of a twin ``SimCamera`` (its known projection, no calibration
    error), over the arena's bounding square."""
    from sim.models.make_scene import ARENA_RADIUS
    from vision.rectify import (
        ArenaModel,
        estimate_camera_position,
        fit_homography,
        undistort_points,
    )

    k, d = camera.intrinsics()
    h = ARENA_RADIUS
    xy = np.array([[x, y] for x in (-h, 0.0, h) for y in (-h, 0.0, h)])
    px = camera.project(np.column_stack([xy, np.zeros(len(xy))]))
    homography = fit_homography(undistort_points(px, k, d), xy)
    position = estimate_camera_position(px, xy, k, d)
    size = (camera.size[1], camera.size[0])  # (width, height)
    return ArenaModel(k, d, size, homography, np.zeros(2), h, position)


def calibrated_locator(rig_id: str, directory: str | None = None) -> BallLocator:
    """The tracker with the arena calibration saved for ``rig_id`` (``ergo calibrate arena``).

    Raises ``calibration.store.CalibrationError`` with a one-line message when the file is
    missing or invalid.
    """
    from calibration.store import load

    return locator_from_calibration(load("arena", rig_id, directory))


def locator_from_calibration(data: dict[str, Any]) -> BallLocator:
    """The tracker from an ``arena`` calibration's data (its model and ball colour ranges)."""
    from vision.rectify import ArenaModel
    from vision.tracker import tracker_config_from_arena

    return tracker_locator(ArenaModel.from_dict(data), tracker_config_from_arena(data))


def rig_ball_locator(config: Any) -> tuple[BallLocator | None, str | None]:
    """The tracker for a physical rig from its arena calibration (found by ``rig_id``, or the
    file named by the rig option ``arena_calibration``), and None; without one, (None, why):
    ball positions are then recorded as unknown (NaN), never guessed, and ``open_run`` warns
    once, or refuses a run whose strategy needs the ball."""
    from calibration.store import CalibrationError, CalibrationMissing
    from explore.rigs.rig import RigError

    try:
        path = config.options.get("arena_calibration")
        if path:
            from calibration.store import load_arena_file

            return locator_from_calibration(load_arena_file(path)), None
        return calibrated_locator(config.rig_id), None
    except (CalibrationMissing, FileNotFoundError) as exc:
        return None, str(exc)
    except CalibrationError as exc:  # a file that is there but wrong: never run without it
        raise RigError(f"{exc} (a damaged or foreign arena calibration is not ignored)") from exc
