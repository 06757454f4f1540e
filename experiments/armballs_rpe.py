"""RPE on Arm-2-Balls against the published RPE: the exploration ratio at 1k/3k/5k/~10k episodes.

RPE draws every motor parameter uniformly in [-1, 1], so its curve depends on the environment
and the motor primitive alone: if ours is not within two published standard deviations of the
published mean at every checkpoint, the environment differs from the original.

The metric is the published one (the original's results/Experiment_Visualization.ipynb): the
fraction of the 30 x 30 cells over [-1, 1]^2 that hold the final ball position of at least one
of the first n episodes. The published checkpoints are n = int(i * 10000 / 30), i = 0..29, so
the last one is 9666. The published figures are read from docs/armballs_published.csv.

    .venv/bin/python experiments/armballs_rpe.py [--seeds 16] [--config arm2balls|armballs]
"""

from __future__ import annotations

import argparse
import csv
import time
from pathlib import Path

import numpy as np
from scipy import stats

from explore.runs.metrics import CellCounter
from sim.armballs import ARM_2_BALLS, ARM_BALLS, ArmBallsEnv

CHECKPOINTS = (1000, 3000, 5000, 9666)  # the published table's columns (episodes)
DOCS = Path(__file__).resolve().parents[1] / "docs"
PUBLISHED = DOCS / "armballs_published.csv"
PUBLISHED_RUNS = DOCS / "armballs_published_runs.csv"


def published(algorithm: str) -> dict[int, tuple[float, float, int]]:
    """iterations -> (mean, sd, runs) of one algorithm in docs/armballs_published.csv."""
    with open(PUBLISHED, newline="") as f:
        return {
            int(r["iterations"]): (float(r["mean"]), float(r["sd"]), int(r["runs"]))
            for r in csv.DictReader(f)
            if r["algorithm"] == algorithm
        }


def published_runs(algorithm: str, iterations: int) -> np.ndarray:
    """Every published run's ratio at one checkpoint (docs/armballs_published_runs.csv)."""
    with open(PUBLISHED_RUNS, newline="") as f:
        return np.array(
            [
                float(r["exploration_30"])
                for r in csv.DictReader(f)
                if r["algorithm"] == algorithm and int(r["iterations"]) == iterations
            ]
        )


def rpe_ratios(env: ArmBallsEnv, seed: int) -> list[float]:
    """One RPE run: exploration ratio at each checkpoint."""
    rng = np.random.default_rng(seed)
    params = rng.uniform(-1.0, 1.0, (max(CHECKPOINTS), env.n_params))
    balls = env.play_batch(params, rng).ball[:, -1]
    out = []
    for n in CHECKPOINTS:
        cells = CellCounter(half_width=1.0, n_bins=30)
        out.append(cells.add(balls[:n]) / cells.n_bins**2)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=16, help="runs (seeds 0..n-1)")
    ap.add_argument("--config", choices=("arm2balls", "armballs"), default="arm2balls")
    args = ap.parse_args()
    env = ArmBallsEnv(ARM_2_BALLS if args.config == "arm2balls" else ARM_BALLS)
    t0 = time.perf_counter()
    ratios = np.array([rpe_ratios(env, s) for s in range(args.seeds)])
    wall = time.perf_counter() - t0
    pub = published("RPE")
    print(f"RPE on {args.config}, {args.seeds} runs x {max(CHECKPOINTS)} episodes ({wall:.1f} s)")
    print(f"{'episodes':>9} {'ours':>15} {'published':>15} {'|diff|/sd_pub':>14} {'Welch p':>8}")
    ok = True
    for i, n in enumerate(CHECKPOINTS):
        m, s = ratios[:, i].mean(), ratios[:, i].std(ddof=1)
        pm, ps, pn = pub[n]
        z = abs(m - pm) / ps
        ok &= z <= 2.0
        p = stats.ttest_ind(ratios[:, i], published_runs("RPE", n), equal_var=False).pvalue
        print(
            f"{n:>9} {m:8.3f} ± {s:.3f} {pm:8.3f} ± {ps:.3f} {z:>14.2f} {p:>8.2f}"
            f"   (runs: ours {len(ratios)}, published {pn})"
        )
    print("within 2 published sd at every checkpoint:", "yes" if ok else "NO")


if __name__ == "__main__":
    main()
