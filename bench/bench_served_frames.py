"""What a served camera frame costs (``ergo twin serve``'s MJPEG producer, one frame at a
time): the plain twin's 240 x 240 ideal frame, and a stand-in's 640 x 480 frame through its
hidden lens (MuJoCo's larger render, then the remap). Prints the median wall and CPU time per
frame of each over ``--frames`` frames, and the share of one core at the stream's 15 frames/s.

    .venv/bin/python bench/bench_served_frames.py [--frames 60] [--seeds 0 7]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from sim.mjpeg_server import DEFAULT_FPS
from sim.standin.hidden import draw_hidden, nominal_rig
from sim.standin.lens import ServedFrames
from sim.standin.served import served_twin


def measure(rig, frames: int) -> tuple[float, float, tuple[int, int]]:
    """(median wall s, median CPU s, render size) per frame."""
    twin, plan = served_twin(rig)
    grab = ServedFrames(twin, plan)
    try:
        grab()  # the renderer is made on the first frame
        wall, cpu = [], []
        for _ in range(frames):
            w0, c0 = time.perf_counter(), time.process_time()
            grab()
            wall.append(time.perf_counter() - w0)
            cpu.append(time.process_time() - c0)
        return float(np.median(wall)), float(np.median(cpu)), plan.size
    finally:
        grab.close()
        twin.close()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 7])
    args = ap.parse_args()
    rigs = [("plain", nominal_rig())] + [(f"stand-in {s}", draw_hidden(s)) for s in args.seeds]
    for name, rig in rigs:
        wall, cpu, size = measure(rig, args.frames)
        w, h = rig.camera.size
        print(
            f"{name}: {w} x {h} frame (render {size[1]} x {size[0]}): {wall * 1000:.1f} ms wall, "
            f"{cpu * 1000:.1f} ms CPU; {cpu * DEFAULT_FPS:.0%} of a core at {DEFAULT_FPS:g} fps"
        )


if __name__ == "__main__":
    main()
