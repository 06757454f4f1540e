"""Benchmark: exploration episodes/s with the rerun recorder saving a .rrd against without.

Both arms run the same number of episodes of the same seed on the twin, in this process,
alternating (off, on, off, on, ...) so that machine load drifts hit both alike. Prints
episodes/s of each and the ratio (recorder on / off); the target is >= 0.9.

    .venv/bin/python bench/bench_rerun.py [--episodes 100] [--repeats 2] [--stride 1]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

if "MUJOCO_GL" not in os.environ and not os.environ.get("DISPLAY"):
    os.environ["MUJOCO_GL"] = "egl"

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from explore.report.recorder import Recorder
from explore.runs.config import RunConfig
from explore.runs.layout import RECORDING_FILE
from explore.runs.open_run import open_run


def run_once(out: Path, episodes: int, record: bool, stride: int) -> tuple[float, float]:
    """One exploration of ``episodes`` episodes into ``out``.

    Returns:
        episodes per wall-clock second and per CPU second of this process (all threads: the
        recorder's background encoder and writer count); the loop only, rig start-up
        excluded, the recorder's flush on close included.
    """
    run = open_run(out, RunConfig(seed=0, episodes=episodes), mode="new")
    recorder = (
        Recorder("save", path=out / RECORDING_FILE, stride=stride, scene=run.rig.scene)
        if record
        else None
    )
    explorer = run.explorer(on_record=recorder.on_record if recorder else None)
    t0, c0 = time.perf_counter(), time.process_time()
    explorer.run(episodes)
    if recorder:
        recorder.close()
    elapsed, cpu = time.perf_counter() - t0, time.process_time() - c0
    run.close()
    return episodes / elapsed, episodes / cpu


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--episodes", type=int, default=100)
    ap.add_argument("--repeats", type=int, default=3, help="alternating pairs (off, on)")
    ap.add_argument("--stride", type=int, default=1, help="recorder stride")
    args = ap.parse_args()
    rates: dict[bool, list[float]] = {False: [], True: []}
    cpu_rates: dict[bool, list[float]] = {False: [], True: []}
    with tempfile.TemporaryDirectory() as tmp:
        run_once(Path(tmp) / "warmup", 5, True, args.stride)  # imports, JIT-free warm caches
        for i in range(args.repeats):
            for record in (False, True):
                out = Path(tmp) / f"{'on' if record else 'off'}-{i}"
                wall, cpu = run_once(out, args.episodes, record, args.stride)
                rates[record].append(wall)
                cpu_rates[record].append(cpu)
        size = sum(p.stat().st_size for p in Path(tmp).glob("on-*/recording.rrd"))
    off, on = float(np.median(rates[False])), float(np.median(rates[True]))
    print(f"episodes per run {args.episodes}, repeats {args.repeats}, stride {args.stride}")
    print(f"without recorder: {off:.1f} episodes/s  (runs: {[round(r, 1) for r in rates[False]]})")
    print(f"with recorder:    {on:.1f} episodes/s  (runs: {[round(r, 1) for r in rates[True]]})")
    print(f"recording size:   {size / args.repeats / args.episodes / 1024:.1f} kB per episode")
    cpu_off, cpu_on = float(np.median(cpu_rates[False])), float(np.median(cpu_rates[True]))
    print(f"per CPU second:   {cpu_off:.1f} without, {cpu_on:.1f} with the recorder")
    print(f"CPU ratio on/off: {cpu_on / cpu_off:.3f} (insensitive to other processes' load)")
    print(f"ratio on/off: {on / off:.3f} (wall clock, medians; target >= 0.9)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
