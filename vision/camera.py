"""The ``Camera`` interface (``connect()``, ``read() -> Frame``, ``disconnect()``); the camera a
source string names is ``vision/make_camera.py``'s."""

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
