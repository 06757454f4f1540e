"""``LatestFrame``: the newest frame of a live camera, for a loop faster than the camera.

The project's ``Camera.read`` returns the newest frame *not yet returned*, waiting for one
(vision/opencv_camera.py): right for an exploration, which takes one frame a tick at the
camera's pace or slower, but a LeRobot loop at 30 or 60 Hz with a 15-30 fps camera would run at
the camera's rate. A thread reads the camera as it delivers and keeps the last frame, already
cut to the overhead square; each observation takes the last one (the same frame twice when the
loop is faster than the camera), as LeRobot's own cameras do (``async_read``). A camera that
fails or goes stale ends the thread, and the next observation raises its error: never an old
frame passed off as new for longer than the camera's own stale limit.
"""

from __future__ import annotations

import threading
from collections.abc import Callable

import numpy as np

from vision.camera import Camera

# How long the first frame may take, s: the camera's connect already waited for one (guess,
# against a hang).
FIRST_FRAME_S = 10.0


class LatestFrame:
    """The newest frame of ``camera`` (connected), as ``convert`` makes it.

    Args:
        camera: a connected live camera.
        convert: a BGR frame -> what the observation holds (the overhead square, RGB).
    """

    def __init__(self, camera: Camera, convert: Callable[[np.ndarray], np.ndarray]) -> None:
        self.camera = camera
        self.convert = convert
        self._lock = threading.Lock()
        self._first = threading.Event()
        self._stop = threading.Event()
        self._image: np.ndarray | None = None
        self._error: BaseException | None = None
        self.frames = 0  # frames read since start
        self._thread = threading.Thread(target=self._run, name="overhead-frames", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                image = self.convert(self.camera.read().image)
            except Exception as exc:  # kept for the next observation to raise
                with self._lock:
                    self._error = exc
                self._first.set()
                return
            with self._lock:
                self._image = image
                self.frames += 1
            self._first.set()

    def get(self) -> np.ndarray:
        """The newest frame; the camera's error once it failed."""
        if not self._first.wait(FIRST_FRAME_S):
            raise TimeoutError(f"no frame from the overhead camera in {FIRST_FRAME_S:.0f} s")
        with self._lock:
            if self._error is not None:
                raise self._error
            assert self._image is not None
            return self._image

    def stop(self) -> None:
        """End the thread (it ends by itself once the camera is disconnected)."""
        self._stop.set()
