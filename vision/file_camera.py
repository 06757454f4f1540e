"""``FileCamera``: replays a folder of images or a video file as a ``vision.Camera``.

Every frame is delivered once, in order (sorted file names for a folder), with a timestamp of
``n / fps`` seconds for the n-th frame delivered, so a replay is deterministic. At the end
``read()`` raises ``CameraError`` unless ``loop`` is set.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from vision.camera import Camera, CameraError, EndOfStream, Frame

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp")
DEFAULT_FPS = 30.0  # frames/s for image folders (and videos that report none): a convention


class FileCamera(Camera):
    """A camera that reads recorded frames.

    Args:
        path: a folder of images (any of ``IMAGE_SUFFIXES``) or a video file.
        fps: frame rate for timestamps, frames/s (default: the video's own, else 30).
        loop: start over after the last frame instead of raising ``CameraError``.
    """

    def __init__(self, path: str | Path, fps: float | None = None, loop: bool = False) -> None:
        super().__init__()
        self.path = Path(path)
        self.loop = loop
        self._fps_arg = fps
        self.fps = fps or DEFAULT_FPS
        self._files: list[Path] = []
        self._cap = None
        self._index = 0  # position in the recording
        self._count = 0  # frames delivered since connect (timestamps keep growing on loop)
        self._frames_in_video: int | None = None

    def __repr__(self) -> str:
        return f"FileCamera({str(self.path)!r})"

    def __len__(self) -> int:
        """Number of frames (a video's count is the container's estimate)."""
        if self._files:
            return len(self._files)
        return int(self._frames_in_video or 0)

    @property
    def index(self) -> int:
        """Index of the next frame to be read."""
        return self._index

    def _connect(self) -> None:
        if not self.path.exists():
            raise CameraError(f"cannot replay {self.path}: no such file or folder")
        self._index = 0
        self._count = 0
        if self.path.is_dir():
            self._files = sorted(
                p for p in self.path.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES
            )
            if not self._files:
                raise CameraError(f"no images ({', '.join(IMAGE_SUFFIXES)}) in folder {self.path}")
            return
        import cv2

        cap = cv2.VideoCapture(str(self.path))
        if not cap.isOpened():
            raise CameraError(f"cannot open video {self.path}: not a video or no codec")
        self._cap = cap
        video_fps = float(cap.get(cv2.CAP_PROP_FPS) or 0.0)
        if self._fps_arg is None and 0.0 < video_fps < 1000.0:
            self.fps = video_fps
        self._frames_in_video = int(cap.get(cv2.CAP_PROP_FRAME_COUNT) or 0)

    def _disconnect(self) -> None:
        if self._cap is not None:
            self._cap.release()
            self._cap = None
        self._files = []

    def _read(self) -> Frame:
        image = self._next_image()
        frame = Frame(image, self._count / self.fps)
        self._index += 1
        self._count += 1
        return frame

    def _next_image(self) -> np.ndarray:
        import cv2

        if self._files:
            if self._index >= len(self._files):
                if not self.loop:
                    raise EndOfStream(f"end of replay: {len(self._files)} frames of {self.path}")
                self._index = 0
            f = self._files[self._index]
            image = cv2.imread(str(f), cv2.IMREAD_COLOR)
            if image is None:
                raise CameraError(f"cannot decode image {f}")
            return image
        ok, image = self._cap.read()
        if not ok and self.loop and self._index > 0:
            self._cap.set(cv2.CAP_PROP_POS_FRAMES, 0)
            self._index = 0
            ok, image = self._cap.read()
        if not ok or image is None:
            raise EndOfStream(f"end of replay: {self._index} frames of {self.path}")
        return image
