"""``make_camera``: the camera a source string names (a device index, a URL, a folder of
images or a video file), the one place a source string is read; beside the ``Camera``
interface (``vision/camera.py``), which the cameras it builds import."""

from __future__ import annotations

from vision.camera import Camera, CameraError
from vision.file_camera import FileCamera
from vision.opencv_camera import OpenCVCamera


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
    if isinstance(source, str) and "://" not in source and files == "replay":
        return FileCamera(source, fps=fps)
    return OpenCVCamera(source, width=width, height=height, fps=fps, fourcc=fourcc)
