"""MP4 files of camera frames, encoded with PyAV as LeRobot datasets encode theirs.

LeRobot's default video encoder (huggingface/lerobot ``lerobot/configs/video.py``,
``VideoEncoderConfig``, read 2026-12-01): AV1 by ``libsvtav1``, pixel format ``yuv420p``, a key
frame every 2 frames (``g``), constant rate factor 30, preset 12 (SVT-AV1 4.x runs it as its
preset 11). The same settings here, so that what reads LeRobot videos reads these: rerun's viewer
decodes AV1 itself (no ffmpeg needed); PyAV, torchcodec and torchvision's VideoReader (up to
0.25) decode it to the same frames (measured: docs/ecosystem.md, bench/bench_video_readers.py).
"""

from __future__ import annotations

import os
from pathlib import Path
from types import TracebackType

import numpy as np

CODEC = "libsvtav1"  # encoder; the stream's codec is "av1"
STREAM_CODEC = "av1"
PIX_FMT = "yuv420p"
GOP = 2  # frames between key frames
CRF = 30
PRESET = 12


def encoder_info() -> dict[str, object]:
    """The ``video.*`` entries LeRobot keeps in ``info.json`` for these settings."""
    return {
        "video.codec": STREAM_CODEC,
        "video.pix_fmt": PIX_FMT,
        "video.is_depth_map": False,
        "video.channels": 3,
        "video.g": GOP,
        "video.crf": CRF,
        "video.preset": PRESET,
        "has_audio": False,
    }


class Mp4Writer:
    """Appends episodes of frames to one MP4 file (AV1, ``fps`` frames per second).

    Args:
        path: the file to write.
        fps: frames per second (the control rate).
        side: frames are (side, side, 3) BGR uint8, side even (yuv420p halves both sides).
    """

    def __init__(self, path: Path, fps: int, side: int) -> None:
        import av

        # SVT-AV1 prints a banner of its settings on every stream unless told otherwise
        os.environ.setdefault("SVT_LOG", "1")  # 1: errors only
        self.path = path
        self.fps = fps
        self.side = side
        self.frames = 0
        self._container = av.open(str(path), mode="w", options={"movflags": "faststart"})
        options = {"g": str(GOP), "crf": str(CRF), "preset": str(PRESET)}
        self._stream = self._container.add_stream(CODEC, rate=fps, options=options)
        self._stream.width = side
        self._stream.height = side
        self._stream.pix_fmt = PIX_FMT

    def add(self, frames: np.ndarray) -> tuple[float, float]:
        """Encode ``frames`` (T, side, side, 3) BGR uint8; returns where they lie in the file,
        (from, to) seconds."""
        import av

        start = self.frames / self.fps
        for image in frames:
            frame = av.VideoFrame.from_ndarray(np.ascontiguousarray(image[..., ::-1]), "rgb24")
            frame.pts = self.frames
            for packet in self._stream.encode(frame):
                self._container.mux(packet)
            self.frames += 1
        return start, self.frames / self.fps

    def close(self) -> None:
        """Flush the encoder and close the file."""
        if self._container is None:
            return
        for packet in self._stream.encode():
            self._container.mux(packet)
        self._container.close()
        self._container = None

    def __enter__(self) -> Mp4Writer:
        return self

    def __exit__(
        self, kind: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()
