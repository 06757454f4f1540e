"""Twin episodes per second for RPE against the bound measured in the same run.

The bound is the cost of the same physics steps plus one overhead render per episode with
nothing else (no DMP, no safety clamp, no store, no metrics). Blocks of RPE episodes and of
their bound alternate, so both see the same machine load. Target: RPE at >= 80% of the bound.

    .venv/bin/python bench/bench_episodes.py [--episodes 200] [--block 10]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from explore.learner.strategies import make_strategy
from explore.rigs.rig import RigConfig, make_rig
from explore.runs.explorer import Explorer
from explore.runs.store import RunStore
from sim.twin import Twin


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--episodes", type=int, default=200)
    ap.add_argument("--block", type=int, default=10)
    args = ap.parse_args()

    rig = make_rig(RigConfig())
    twin = rig.twin
    bound_twin = Twin(render_size=twin.render_size)  # a second twin: same model, own state
    rpe_s = bound_s = 0.0
    steps_total = 0
    with tempfile.TemporaryDirectory() as tmp, rig:
        store = RunStore.create(Path(tmp) / "run", {"bench": True})
        explorer = Explorer(rig, make_strategy("rpe"), store, seed=0)
        twin.render()
        bound_twin.render()  # warm both renderers up outside the timings
        rng = np.random.default_rng(0)
        for first in range(0, args.episodes, args.block):
            ks = range(first, min(first + args.block, args.episodes))
            steps = []
            for k in ks:
                t_sim = twin.time
                t0 = time.perf_counter()
                explorer.step(k)
                rpe_s += time.perf_counter() - t0
                steps.append(round((twin.time - t_sim) / twin.timestep))
            t0 = time.perf_counter()
            for n in steps:
                bound_twin.set_targets(rng.uniform(-1, 1, 6))
                bound_twin.step(n * twin.timestep)
                bound_twin.render()
            bound_s += time.perf_counter() - t0
            steps_total += sum(steps)
        store.close()

    n = args.episodes
    rpe_rate, bound_rate = n / rpe_s, n / bound_s
    print(f"episodes         : {n} (mean {steps_total / n:.0f} physics steps each)")
    print(f"RPE episodes/s   : {rpe_rate:.1f}")
    print(f"bound episodes/s : {bound_rate:.1f} (same steps + 1 render per episode)")
    print(f"ratio            : {rpe_rate / bound_rate:.2f} (target >= 0.80)")


if __name__ == "__main__":
    main()
