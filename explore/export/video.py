"""MP4 files of camera frames, encoded with PyAV as LeRobot datasets encode theirs.

LeRobot's default video encoder (huggingface/lerobot ``lerobot/configs/video.py``,
``VideoEncoderConfig``, read 2026-12-01): AV1 by ``libsvtav1``, pixel format ``yuv420p``, a key
frame every 2 frames (``g``), constant rate factor 30, preset 12 (SVT-AV1 4.x runs it as its
preset 11). The same settings here, so that what reads LeRobot videos reads these: rerun's viewer
decodes AV1 itself (no ffmpeg needed); PyAV, torchcodec and torchvision's VideoReader (up to
0.25) decode it to the same frames (measured: docs/ecosystem.md, bench/bench_video_readers.py).

Run as root, SVT-AV1 takes the highest real-time priority: its encoder threads and the thread
that feeds it frames become SCHED_FIFO at 99 (measured with PyAV 18.1.0's libSvtAv1Enc 4.1.0:
``os.sched_getscheduler`` on every thread of ``/proc/self/task`` after the first frame; SVT-AV1's
``EbThreads.c`` asks for priority 99 whenever ``geteuid()`` is 0). A CPU-bound encoder at 99
outranks an arm's controller and its signal watcher (SCHED_FIFO 10, ``robot.signals``) on every
core, and every process the exporting process starts after inherits the policy. So after each
call into the encoder, ``Mp4Writer`` puts every thread that changed back (``ordinary_threads``).
"""

from __future__ import annotations

import contextlib
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


def thread_schedules() -> dict[int, tuple[int, int]]:
    """{thread id: (scheduling policy, real-time priority)} of this process's threads (empty
    where there is no ``/proc`` or no ``sched_getscheduler``)."""
    out: dict[int, tuple[int, int]] = {}
    try:
        tids = [int(t) for t in os.listdir("/proc/self/task")]
        for tid in tids:
            with contextlib.suppress(ProcessLookupError):  # a thread that ended meanwhile
                out[tid] = (os.sched_getscheduler(tid), os.sched_getparam(tid).sched_priority)
    except (AttributeError, OSError):
        return {}
    return out


def ordinary_threads(before: dict[int, tuple[int, int]]) -> int:
    """Undo what a library did to this process's scheduling since ``before``
    (``thread_schedules()``): a thread of ``before`` whose policy or priority changed gets its
    own back, a thread started since at a real-time policy (FIFO, RR) gets the ordinary one
    (SCHED_OTHER). Returns how many threads were changed (0 where not permitted)."""
    changed = 0
    for tid, now in thread_schedules().items():
        was = before.get(tid, (os.SCHED_OTHER, 0))
        if now == was or (tid not in before and now[0] not in (os.SCHED_FIFO, os.SCHED_RR)):
            continue
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.sched_setscheduler(tid, was[0], os.sched_param(was[1]))
            changed += 1
    return changed


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
        self._schedules = thread_schedules()  # what the encoder may change (module docstring)
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
            try:
                for packet in self._stream.encode(frame):
                    self._container.mux(packet)
            finally:
                ordinary_threads(self._schedules)
            self.frames += 1
        return start, self.frames / self.fps

    def close(self) -> None:
        """Flush the encoder and close the file."""
        if self._container is None:
            return
        try:
            for packet in self._stream.encode():
                self._container.mux(packet)
            self._container.close()
        finally:
            self._container = None
            ordinary_threads(self._schedules)

    def __enter__(self) -> Mp4Writer:
        return self

    def __exit__(
        self, kind: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()
