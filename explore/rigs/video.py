"""The rig option ``record_video``: the overhead camera captured at every control tick of a
movement, as square frames, for datasets at the control rate (``ergo export lerobot``).

Every rig takes it (the twin and the physical rigs). ``record_video=SIDE`` keeps, for each
episode, the frames (T, SIDE, SIDE, 3) BGR uint8 in ``RUN/frames/`` (``explore.runs.store``),
the frame of tick i taken just before that tick's command, when the joints were last read.
The square is the view the 64 px observation is made of: on the twin and on a physical rig
without an arena calibration the centre square of the camera's view
(``vision.observation.square_observation``), on a physical rig with one the twin's view of its
frame (``explore.rigs.ball.CameraSensor.observe``). A live camera gives its latest frame at
each tick: a camera slower than the control rate (30 fps against 40 Hz) repeats a frame now and
then.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from explore.options import BadOption
from vision.camera import Camera
from vision.observation import square_observation

# Frame side, pixels: even (the yuv420p video LeRobot datasets use halves both sides), at least
# 16 (below it the ball is a pixel or two) and at most 512 (a 5000-episode run would keep some
# 100 GB of frames at 512; guesses on the safe side).
VIDEO_SIDE = (16, 512)
VIDEO_EXPECTED = f"0 (none) or an even number of pixels in [{VIDEO_SIDE[0]}, {VIDEO_SIDE[1]}]"


@dataclass(frozen=True)
class VideoOptions:
    """Options every rig takes.

    Attributes:
        record_video: side of the square frames of the overhead camera kept at every control
            tick of a movement, pixels (default 0: none); e.g. 128.
    """

    record_video: int = field(default=0, metadata={"expected": VIDEO_EXPECTED})

    def __post_init__(self) -> None:
        side = self.record_video
        lo, hi = VIDEO_SIDE
        if side != 0 and not (lo <= side <= hi and side % 2 == 0):
            raise BadOption("record_video", f"must be {VIDEO_EXPECTED}, got {side}")


def camera_video_frame(
    camera: Camera,
    side: int,
    observe: Callable[[np.ndarray, int], np.ndarray] = square_observation,
) -> Callable[[], np.ndarray] | None:
    """() -> ``observe`` of ``camera``'s latest frame at (side, side), BGR uint8 (default its
    centre square); None when ``side`` is 0."""
    if side == 0:
        return None
    return lambda: observe(camera.read().image, side)
