"""FileCamera: replay of an image folder and of a video file, in order, with deterministic
timestamps, looping, and clear errors."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from vision.camera import CameraError, EndOfStream
from vision.file_camera import FileCamera


def _frame(i: int) -> np.ndarray:
    """A 48x64 frame whose mean grey level encodes its index."""
    img = np.full((48, 64, 3), 10 + 20 * i, np.uint8)
    cv2.putText(img, str(i), (5, 40), cv2.FONT_HERSHEY_SIMPLEX, 1.0, (255, 255, 255), 2)
    return img


@pytest.fixture
def folder(tmp_path):
    for i in range(5):
        cv2.imwrite(str(tmp_path / f"frame_{i:03d}.png"), _frame(i))
    (tmp_path / "notes.txt").write_text("not an image")
    return tmp_path


def test_folder_replays_in_order_then_ends(folder):
    with FileCamera(folder, fps=10.0) as cam:
        assert len(cam) == 5
        frames = [cam.read() for _ in range(5)]
        with pytest.raises(EndOfStream, match="end of replay"):
            cam.read()
    for i, f in enumerate(frames):
        assert f.image.shape == (48, 64, 3) and f.image.dtype == np.uint8
        assert np.array_equal(f.image, _frame(i))  # PNG is lossless
        assert f.timestamp == pytest.approx(i / 10.0)


def test_folder_loops_with_growing_timestamps(folder):
    with FileCamera(folder, loop=True) as cam:
        frames = [cam.read() for _ in range(7)]
    assert np.array_equal(frames[5].image, frames[0].image)
    assert [f.timestamp for f in frames] == pytest.approx([i / 30.0 for i in range(7)])


def test_video_replay(tmp_path):
    path = tmp_path / "clip.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*"MJPG"), 25.0, (64, 48))
    for i in range(6):
        writer.write(_frame(i))
    writer.release()
    with FileCamera(path) as cam:
        assert cam.fps == pytest.approx(25.0)
        frames = [cam.read() for _ in range(6)]
        with pytest.raises(EndOfStream, match="end of replay"):
            cam.read()
    means = [f.image.mean() for f in frames]
    assert means == sorted(means)  # the frames come back in order (JPEG: approximately equal)
    assert frames[3].timestamp == pytest.approx(3 / 25.0)


def test_errors(tmp_path):
    with pytest.raises(CameraError, match="no such file"):
        FileCamera(tmp_path / "missing").connect()
    with pytest.raises(CameraError, match="no images"):
        FileCamera(tmp_path).connect()
    bad = tmp_path / "bad.avi"
    bad.write_text("not a video")
    with pytest.raises(CameraError, match="cannot open video"):
        FileCamera(bad).connect()
    with pytest.raises(CameraError, match="not connected"):
        FileCamera(tmp_path).read()
