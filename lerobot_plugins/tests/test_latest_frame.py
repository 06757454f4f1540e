"""A live camera slower than LeRobot's loop does not slow the loop down: each observation takes
the newest frame, and a camera that fails makes the next observation fail."""

from __future__ import annotations

import time

import numpy as np
import pytest
from lerobot_robot_ergo_jr.latest_frame import LatestFrame

from vision.camera import Camera, CameraError, Frame


class SlowCamera(Camera):
    """A camera giving a new frame every ``period`` s (its value: the frame's number), then
    failing after ``frames`` of them; ``read`` waits for a new one, as vision's live cameras."""

    def __init__(self, period: float, frames: int = 10_000) -> None:
        super().__init__()
        self.period, self.frames, self.n = period, frames, 0

    def _connect(self) -> None:
        pass

    def _disconnect(self) -> None:
        pass

    def _read(self) -> Frame:
        time.sleep(self.period)
        self.n += 1
        if self.n > self.frames:
            raise CameraError("camera 'slow' is stale: no new frame for 1.0 s")
        return Frame(np.full((4, 4, 3), self.n % 256, np.uint8), time.monotonic())


def test_the_loop_runs_at_its_own_rate_with_the_newest_frame():
    camera = SlowCamera(period=1 / 15)
    camera.connect()
    frames = LatestFrame(camera, lambda image: image)
    try:
        frames.get()
        t0, seen = time.monotonic(), []
        while time.monotonic() - t0 < 1.0:
            seen.append(int(frames.get()[0, 0, 0]))
            time.sleep(1 / 60)
        took = time.monotonic() - t0
    finally:
        frames.stop()
    assert len(seen) / took > 40  # a 60 Hz loop, not the camera's 15 frames/s
    assert seen == sorted(seen) and seen[-1] - seen[0] >= 8  # the newest frame each time


def test_a_failed_camera_fails_the_next_observation():
    camera = SlowCamera(period=0.01, frames=3)
    camera.connect()
    frames = LatestFrame(camera, lambda image: image)
    time.sleep(0.3)
    with pytest.raises(CameraError, match="stale"):
        frames.get()
