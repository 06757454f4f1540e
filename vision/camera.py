"""The ``Camera`` interface (``connect()``, ``read() -> Frame``, ``disconnect()``) and
``make_camera``, the camera a source string names."""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np


class CameraError(RuntimeError):
    """A camera could not be opened or stopped delivering frames."""


class EndOfStream(CameraError):
    """A recorded source (a video file, a folder of images) has no frame left: the end of a
    replay, not a failure; a command that reads a recording to its end stops there."""


@dataclass
class Frame:
    """One camera image.

    Attributes:
        image: BGR image, shape (H, W, 3), uint8.
        timestamp: seconds (``time.monotonic`` for real cameras, the twin's clock in sim).
    """

    image: np.ndarray
    timestamp: float


class Camera(ABC):
    """Abstract camera; a context manager that connects on entry and disconnects on exit."""

    def __init__(self) -> None:
        self._connected = False

    @property
    def is_connected(self) -> bool:
        return self._connected

    def connect(self) -> None:
        if not self._connected:
            self._connect()
            self._connected = True

    def disconnect(self) -> None:
        if self._connected:
            try:
                self._disconnect()
            finally:
                self._connected = False

    def read(self) -> Frame:
        if not self._connected:
            raise CameraError(f"{type(self).__name__} is not connected: call connect() first")
        return self._read()

    def __enter__(self) -> Camera:
        self.connect()
        return self

    def __exit__(self, *exc: object) -> None:
        self.disconnect()

    @abstractmethod
    def _connect(self) -> None: ...

    @abstractmethod
    def _disconnect(self) -> None: ...

    @abstractmethod
    def _read(self) -> Frame: ...


def make_camera(
    source: int | str,
    width: int | None = None,
    height: int | None = None,
    fps: float | None = None,
    fourcc: str | None = None,
    *,
    files: str = "replay",
) -> Camera:
    """The camera a source names, not connected: the one place a source string is read.

    A device index (an int, or a string of digits: ``0`` is /dev/video0) or a URL
    (``http://127.0.0.1:PORT/stream.mjpg``) is a live ``OpenCVCamera``. A folder of images or a
    video file is replayed frame by frame (``FileCamera``: deterministic, every frame once), or,
    with ``files="live"``, played by OpenCV at its own rate like a live camera (a rig on the
    wall clock). ``width``, ``height``, ``fps`` and ``fourcc`` are requested modes (ignored by a
    replay, except ``fps`` for its timestamps).

    Raises:
        CameraError: a source that is none of these (empty, negative, not an int or a string).
    """
    if files not in ("replay", "live"):
        raise ValueError(f"files must be 'replay' or 'live', got {files!r}")
    if isinstance(source, str) and source.strip().isdigit():
        source = int(source.strip())
    bad = isinstance(source, bool) or not isinstance(source, int | str) or source == ""
    if bad or (isinstance(source, int) and source < 0):
        raise CameraError(f"camera must be a device index, video path or URL, got {source!r}")
    from vision.opencv_camera import OpenCVCamera

    if isinstance(source, str) and "://" not in source and files == "replay":
        from vision.file_camera import FileCamera

        return FileCamera(source, fps=fps)
    return OpenCVCamera(source, width=width, height=height, fps=fps, fourcc=fourcc)
