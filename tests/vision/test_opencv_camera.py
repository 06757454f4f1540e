"""OpenCVCamera on a video file and on a local MJPEG stream (127.0.0.1), its settings check,
and its clear errors on bad sources and dead streams."""

from __future__ import annotations

import logging
import os
import subprocess
import sys
import time
from pathlib import Path

import cv2
import numpy as np
import pytest

from vision.camera import CameraError, EndOfStream
from vision.opencv_camera import OpenCVCamera


def _video(path, n=10, fps=50.0, size=(64, 48)):
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*"MJPG"), fps, size)
    for i in range(n):
        writer.write(np.full((size[1], size[0], 3), 20 * i, np.uint8))
    writer.release()
    return path


def test_video_file_frames_then_end(tmp_path, caplog):
    path = _video(tmp_path / "clip.avi")
    caplog.set_level(logging.WARNING)
    cam = OpenCVCamera(str(path), width=320, fps=50)
    with cam:
        assert cam.settings.width == 64 and cam.settings.height == 48
        assert cam.settings.fps == pytest.approx(50.0)
        # The file cannot be resized: the camera says so instead of pretending.
        assert cam.settings_warnings == ["width 320 requested, frames are 64 px wide"]
        assert "ignored a setting" in caplog.text
        frames = []
        with pytest.raises(EndOfStream, match="ended"):
            for _ in range(100):
                frames.append(cam.read())
    assert 1 <= len(frames) <= 10
    assert all(f.image.shape == (48, 64, 3) for f in frames)
    stamps = [f.timestamp for f in frames]
    assert stamps == sorted(stamps)
    assert not cam.is_connected


def test_numeric_string_is_a_device_index():
    assert OpenCVCamera("3").source == 3
    with pytest.raises(ValueError, match="fourcc"):
        OpenCVCamera(0, fourcc="MJPEG")


@pytest.mark.parametrize(
    ("source", "match"),
    [
        ("/nonexistent/clip.avi", "no such file"),
        (57, "cannot open camera device 57"),
        ("http://127.0.0.1:9/stream.mjpg", "cannot open stream"),
    ],
)
def test_bad_sources_raise_clear_errors(source, match):
    with pytest.raises(CameraError, match=match):
        OpenCVCamera(source, open_timeout_s=2.0).connect()


def test_not_a_video(tmp_path):
    bad = tmp_path / "clip.avi"
    bad.write_text("hello")
    with pytest.raises(CameraError, match="cannot open video file"):
        OpenCVCamera(str(bad)).connect()


def test_mjpeg_stream_and_dead_stream():
    from sim.mjpeg_server import MjpegServer

    count = {"n": 0}

    def grab() -> np.ndarray:
        count["n"] += 1
        img = np.zeros((48, 64, 3), np.uint8)
        img[:, :, 1] = min(255, 5 * count["n"])
        return img

    server = MjpegServer(grab, fps=30.0)
    server.start()
    try:
        cam = OpenCVCamera(server.url, stale_after_s=1.0, max_failures=5, open_timeout_s=5.0)
        cam.connect()
        try:
            a = cam.read()
            b = cam.read()
            assert a.image.shape == (48, 64, 3)
            assert b.timestamp > a.timestamp  # a new frame each read, not the same one twice
            server.stop()
            with pytest.raises(CameraError, match=r"stale|failed|ended"):
                deadline = time.monotonic() + 20.0
                while time.monotonic() < deadline:
                    cam.read()
        finally:
            cam.disconnect()
    finally:
        server.stop()


def test_a_device_that_does_not_open_is_one_line_without_opencvs_warnings():
    """OpenCV printed "[ WARN:0@0.011] ... can't open camera by index" and "... should be
    configured with libavdevice" before ergo's own line (to the process's stderr, not Python's:
    a child process is read here)."""
    env = {k: v for k, v in os.environ.items() if k != "OPENCV_LOG_LEVEL"}
    env["PYTHONPATH"] = str(Path(__file__).resolve().parents[2])
    proc = subprocess.run(
        [sys.executable, "-m", "explore.cli", "track", "--camera", "57"],
        capture_output=True, text=True, env=env, timeout=120,
    )  # fmt: skip
    assert proc.returncode == 2
    assert proc.stderr.splitlines() == [
        "ergo: error: cannot open camera device 57: no such device or it is busy "
        "(run `ergo find-cameras` to list the devices that open)"
    ]
