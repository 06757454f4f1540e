"""What the physical rigs (``dynamixel``, ``canopen``) share: the camera options and the camera
they name, the joint calibration options, the arena calibration that locates the ball, and
their scene (the arena as built, the twin's dimensions)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from explore.learner.scene import TWIN_ARENA, Scene
from explore.options import BadOption
from explore.rigs.rig import RigError
from explore.rigs.video import VideoOptions
from vision.camera import Camera, CameraError, make_camera

CAMERA = "a device index, video path or URL"


@dataclass(frozen=True)
class HardwareOptions(VideoOptions):
    """Options every physical rig takes (and ``record_video``: ``explore.rigs.video``).

    Attributes:
        camera: device index (``0``), video path or URL (``http://127.0.0.1:PORT/stream.mjpg``
            from ``ergo twin serve``); default 0. A video is played at its own rate, like a
            live camera.
        camera_width, camera_height, camera_fps: requested camera mode (optional).
        arena_calibration: the arena calibration file (default: the rig's, found by its id).
        directions, offsets: per joint +1/-1 and rad (default +1 and 0; the joint calibration
            sets them).
    """

    camera: int | str = field(default=0, metadata={"expected": CAMERA})
    camera_width: int | None = None
    camera_height: int | None = None
    camera_fps: float | None = None
    arena_calibration: str | None = None
    directions: tuple[float, ...] | None = None
    offsets: tuple[float, ...] | None = None

    def __post_init__(self) -> None:
        super().__post_init__()
        if isinstance(self.camera, int) and self.camera < 0:
            raise BadOption("camera", f"must be {CAMERA}, got {self.camera!r}")


def rig_camera(options: HardwareOptions, rig: str) -> Camera:
    """The camera of a physical rig (unconnected); a ``RigError`` for a source it cannot be."""
    try:
        return make_camera(
            options.camera, options.camera_width, options.camera_height, options.camera_fps,
            files="live",
        )  # fmt: skip
    except CameraError as exc:
        raise RigError(f"rig {rig!r}: {exc}") from exc


def per_joint(options: HardwareOptions, key: str, n: int, rig: str) -> tuple[float, ...] | None:
    """``options.<key>`` (directions or offsets) checked to hold ``n`` values, or None."""
    value: Any = getattr(options, key)
    if value is not None and len(value) != n:
        raise RigError(f"rig {rig!r}: option {key} needs {n} values, got {list(value)}")
    return value


def scene(config: Any, options: Any) -> Scene:
    """A physical rig's scene: the Ergo Jr arena as built (sim/models/make_scene.py)."""
    return TWIN_ARENA
