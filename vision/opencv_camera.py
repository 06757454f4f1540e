"""``OpenCVCamera``: a ``vision.Camera`` on ``cv2.VideoCapture`` (device index, file or URL).

A reader thread grabs frames continuously so that ``read()`` returns the *latest* frame rather
than one that waited in the driver's queue. Requested width, height, fps and FOURCC are set and
then read back: a device that ignores them is reported with a warning (``settings_warnings``)
instead of silently running at another mode (the pain point of lerobot issue #2274).
"""

from __future__ import annotations

import logging
import os
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from vision.camera import Camera, CameraError, EndOfStream, Frame


@contextmanager
def opencv_errors_only() -> Iterator[None]:
    """OpenCV's own log at ERROR while opening captures, unless the user set
    ``OPENCV_LOG_LEVEL``: a device that does not open made OpenCV print WARN lines first (V4L2
    "can't open camera by index", FFMPEG "should be configured with libavdevice"), before the
    one line that says so."""
    import cv2

    if "OPENCV_LOG_LEVEL" in os.environ:
        yield
        return
    level = cv2.utils.logging.getLogLevel()
    cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_ERROR)
    try:
        yield
    finally:
        cv2.utils.logging.setLogLevel(level)


log = logging.getLogger(__name__)

# Guesses, chosen to be generous for USB webcams (which can take ~1 s to deliver a first frame
# after a mode change) and to fail within seconds on a dead stream.
OPEN_TIMEOUT_S = 5.0  # guess: how long to wait for opening and for the first frame
STALE_AFTER_S = 2.0  # guess: read() fails when no new frame arrived for this long
MAX_CONSECUTIVE_FAILURES = 30  # guess: about 1 s of failed grabs at 30 fps
FILE_FPS_FALLBACK = 30.0  # guess: pace for video files whose container reports no fps
FPS_TOLERANCE = 0.5  # frames/s: a read-back fps this close to the request counts as honoured


@dataclass(frozen=True)
class CaptureSettings:
    """What the device reports after opening (0 or "" where it reports nothing).

    Attributes:
        width, height: pixels (from the first frame actually delivered).
        fps: frames per second reported by the backend.
        fourcc: four-character code reported by the backend.
        backend: the OpenCV backend's name (e.g. "V4L2", "FFMPEG").
    """

    width: int
    height: int
    fps: float
    fourcc: str
    backend: str


def _decode_fourcc(value: float) -> str:
    code = int(value)
    if code <= 0:
        return ""
    chars = [chr((code >> (8 * i)) & 0xFF) for i in range(4)]
    return "".join(c if c.isprintable() else "?" for c in chars)


def _is_url(source: str) -> bool:
    return "://" in source


class OpenCVCamera(Camera):
    """A camera opened with OpenCV.

    Args:
        source: device index (``0`` for /dev/video0), a video file path, or a URL (e.g. an
            MJPEG stream ``http://127.0.0.1:PORT/stream.mjpg``). A string of digits is taken
            as a device index.
        width, height: requested frame size, pixels (None: the device's default).
        fps: requested frame rate, frames/s (None: default).
        fourcc: requested pixel format, four characters such as ``"MJPG"`` or ``"YUYV"``.
        open_timeout_s: seconds to wait for opening and for the first frame.
        stale_after_s: ``read()`` raises ``CameraError`` when no new frame came for this long.
        max_failures: consecutive failed grabs after which the stream is declared dead.
        realtime_files: pace video files at their own frame rate, like a live camera (True),
            or decode them as fast as possible (False; the latest frame then races ahead).

    ``read()`` returns the newest frame not yet returned, waiting for one if needed; its
    timestamp is ``time.monotonic()`` at grab time. After connecting, ``settings`` holds what
    the device reports and ``settings_warnings`` lists every requested setting it ignored.
    """

    def __init__(
        self,
        source: int | str,
        width: int | None = None,
        height: int | None = None,
        fps: float | None = None,
        fourcc: str | None = None,
        *,
        open_timeout_s: float = OPEN_TIMEOUT_S,
        stale_after_s: float = STALE_AFTER_S,
        max_failures: int = MAX_CONSECUTIVE_FAILURES,
        realtime_files: bool = True,
    ) -> None:
        super().__init__()
        if isinstance(source, str) and source.strip().isdigit():
            source = int(source.strip())
        if fourcc is not None and len(fourcc) != 4:
            raise ValueError(f"fourcc must be 4 characters, got {fourcc!r}")
        self.source: int | str = source
        self.width = width
        self.height = height
        self.fps = fps
        self.fourcc = fourcc
        self.open_timeout_s = float(open_timeout_s)
        self.stale_after_s = float(stale_after_s)
        self.max_failures = int(max_failures)
        self.realtime_files = realtime_files
        self.settings: CaptureSettings | None = None
        self.settings_warnings: list[str] = []
        self._cap = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._cond = threading.Condition()
        self._latest: Frame | None = None
        self._seq = 0
        self._returned_seq = 0
        self._last_new_frame_t = 0.0
        self._error: str | None = None
        self._ended = False  # the error is a video file's end (EndOfStream)

    def __repr__(self) -> str:
        return f"OpenCVCamera({self.source!r})"

    # ---- opening ---------------------------------------------------------------------------
    @property
    def _is_file(self) -> bool:
        return isinstance(self.source, str) and not _is_url(self.source)

    def _open_capture(self):
        import cv2

        timeout_ms = int(self.open_timeout_s * 1000)
        params = [
            cv2.CAP_PROP_OPEN_TIMEOUT_MSEC,
            timeout_ms,
            cv2.CAP_PROP_READ_TIMEOUT_MSEC,
            timeout_ms,
        ]
        if isinstance(self.source, int):
            # V4L2 on Linux honours the mode properties; elsewhere let OpenCV choose.
            api = cv2.CAP_V4L2 if os.name == "posix" and Path("/dev").exists() else cv2.CAP_ANY
            cap = cv2.VideoCapture(self.source, api, params)
            if not cap.isOpened() and api != cv2.CAP_ANY:
                cap = cv2.VideoCapture(self.source, cv2.CAP_ANY, params)
            if not cap.isOpened():
                raise CameraError(
                    f"cannot open camera device {self.source}: no such device or it is busy "
                    "(run `ergo find-cameras` to list the devices that open)"
                )
            return cap
        if self._is_file and not Path(self.source).exists():
            raise CameraError(f"cannot open video source {self.source!r}: no such file")
        cap = cv2.VideoCapture(self.source, cv2.CAP_FFMPEG, params)
        if not cap.isOpened():
            cap = cv2.VideoCapture(self.source, cv2.CAP_ANY)
        if not cap.isOpened():
            kind = "stream" if _is_url(str(self.source)) else "video file"
            raise CameraError(
                f"cannot open {kind} {self.source!r}: unreachable, not a video, or no codec"
            )
        return cap

    def _apply_settings(self, cap) -> None:
        """Set the requested mode; order matters on V4L2: FOURCC, then size, then fps."""
        import cv2

        if self.fourcc is not None:
            cap.set(cv2.CAP_PROP_FOURCC, cv2.VideoWriter.fourcc(*self.fourcc))
        if self.width is not None:
            cap.set(cv2.CAP_PROP_FRAME_WIDTH, float(self.width))
        if self.height is not None:
            cap.set(cv2.CAP_PROP_FRAME_HEIGHT, float(self.height))
        if self.fps is not None:
            cap.set(cv2.CAP_PROP_FPS, float(self.fps))

    def _check_settings(self, cap, first: np.ndarray) -> None:
        """Compare what was asked with what the device reports and delivers; warn on mismatch."""
        import cv2

        h, w = first.shape[:2]
        fps = float(cap.get(cv2.CAP_PROP_FPS) or 0.0)
        fourcc = _decode_fourcc(cap.get(cv2.CAP_PROP_FOURCC))
        try:
            backend = cap.getBackendName()
        except cv2.error:
            backend = ""
        self.settings = CaptureSettings(w, h, fps, fourcc, backend)
        warnings: list[str] = []
        if self.width is not None and w != self.width:
            warnings.append(f"width {self.width} requested, frames are {w} px wide")
        if self.height is not None and h != self.height:
            warnings.append(f"height {self.height} requested, frames are {h} px high")
        if self.fps is not None and abs(fps - self.fps) > FPS_TOLERANCE:
            warnings.append(f"fps {self.fps:g} requested, device reports {fps:g}")
        if self.fourcc is not None and fourcc.upper() != self.fourcc.upper():
            warnings.append(f"FOURCC {self.fourcc} requested, device reports {fourcc or 'none'}")
        self.settings_warnings = warnings
        for msg in warnings:
            log.warning("camera %r ignored a setting: %s", self.source, msg)

    def _connect(self) -> None:
        with opencv_errors_only():
            cap = self._open_capture()
        try:
            self._apply_settings(cap)
            deadline = time.monotonic() + self.open_timeout_s
            ok, first = cap.read()
            while not ok and time.monotonic() < deadline:
                time.sleep(0.02)
                ok, first = cap.read()
            if not ok or first is None:
                raise CameraError(
                    f"camera {self.source!r} opened but delivered no frame "
                    f"within {self.open_timeout_s:g} s"
                )
            first = self._to_bgr(first)
            self._check_settings(cap, first)
        except BaseException:
            cap.release()
            raise
        self._cap = cap
        self._stop.clear()
        self._error = None
        self._ended = False
        now = time.monotonic()
        with self._cond:
            self._latest = Frame(first, now)
            self._seq = 1
            self._returned_seq = 0
            self._last_new_frame_t = now
        self._thread = threading.Thread(
            target=self._reader, name=f"OpenCVCamera({self.source!r})", daemon=True
        )
        self._thread.start()

    @staticmethod
    def _to_bgr(image: np.ndarray) -> np.ndarray:
        import cv2

        if image.ndim == 2:
            return cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
        if image.shape[2] == 4:
            return cv2.cvtColor(image, cv2.COLOR_BGRA2BGR)
        return image

    # ---- the reader thread -----------------------------------------------------------------
    def _frame_period(self) -> float:
        """Seconds between frames to pace a video file; 0 for live sources."""
        import cv2

        if not (self._is_file and self.realtime_files):
            return 0.0
        fps = float(self._cap.get(cv2.CAP_PROP_FPS) or 0.0)
        return 1.0 / (fps if 0.0 < fps < 1000.0 else FILE_FPS_FALLBACK)

    def _reader(self) -> None:
        period = self._frame_period()
        failures = 0
        next_t = time.monotonic() + period
        while not self._stop.is_set():
            if period:
                delay = next_t - time.monotonic()
                if delay > 0 and self._stop.wait(delay):
                    break
                next_t += period
            try:
                ok, image = self._cap.read()
            except Exception as exc:  # any backend failure counts as a failed read
                ok, image = False, None
                log.debug("camera %r read raised %s", self.source, exc)
            if ok and image is not None:
                failures = 0
                frame = Frame(self._to_bgr(image), time.monotonic())
                with self._cond:
                    self._latest = frame
                    self._seq += 1
                    self._last_new_frame_t = frame.timestamp
                    self._cond.notify_all()
                continue
            failures += 1
            if self._is_file and failures >= 2:
                reason = f"video file {self.source!r} ended"
            elif failures >= self.max_failures:
                reason = f"camera {self.source!r} failed {failures} reads in a row"
            else:
                time.sleep(0.01)
                continue
            with self._cond:
                self._error = reason
                self._ended = self._is_file and failures >= 2
                self._cond.notify_all()
            return

    # ---- Camera interface ------------------------------------------------------------------
    def _read(self) -> Frame:
        """The newest frame not yet returned; waits up to ``stale_after_s`` for a new one."""
        deadline = time.monotonic() + self.stale_after_s
        with self._cond:
            while self._seq <= self._returned_seq:
                if self._error is not None:
                    raise (EndOfStream if self._ended else CameraError)(self._error)
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    age = time.monotonic() - self._last_new_frame_t
                    raise CameraError(
                        f"camera {self.source!r} is stale: no new frame for {age:.1f} s"
                    )
                self._cond.wait(remaining)
            self._returned_seq = self._seq
            assert self._latest is not None
            return self._latest

    def _disconnect(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=self.open_timeout_s + 1.0)
            self._thread = None
        if self._cap is not None:
            self._cap.release()
            self._cap = None
