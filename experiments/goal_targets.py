"""Where a run's goals point in the arena (docs/results_vae.md F11): for each goal episode, the
stored outcome nearest to its goal in the run's own goal space (outcome only, no context),
and where that outcome left the ball.

    .venv/bin/python experiments/goal_targets.py CAMPAIGN --strategies rge-efr,rge-sae,rge-vae \
        [--seeds 700-707] [--episodes 1500]

Per strategy, means over its runs of: the largest share of goals pointing into one 30-degree
sector of the ring (1/12 = 0.083 if even), the sectors receiving under 2% of them, and the
distance from a goal to its nearest outcome over the outcomes' median distance to their mean
(how far from what was reached the goals lie; goal spaces of different units compare).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from explore.runs.store import RunStore
from vision.cli import parse_seeds

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # testkit/, not installed
from testkit.inverse_model import goal_space_vectors

SECTOR_DEG = 30


def run_targets(run: Path, episodes: int) -> tuple[float, int, float]:
    recs = RunStore.read(run).records[:episodes]
    _, out, modules = goal_space_vectors(run, recs, None)
    balls = np.array([np.asarray(r.ball, dtype=float)[:2] for r in recs])
    targets, gaps = [], []
    for k, r in enumerate(recs):
        if r.kind not in ("explore", "exploit") or k == 0:
            continue
        seen = out[:k][:, modules[r.module]]
        ok = np.all(np.isfinite(seen), axis=1)
        d = np.where(ok, np.linalg.norm(seen - r.goal, axis=1), np.inf)
        j = int(np.argmin(d))
        spread = np.median(np.linalg.norm(seen[ok] - seen[ok].mean(axis=0), axis=1))
        targets.append(balls[j])
        gaps.append(d[j] / spread if spread > 0 else np.nan)
    t = np.array(targets)
    angle = np.degrees(np.arctan2(t[:, 1], t[:, 0]))
    share = np.histogram(angle, bins=np.arange(-180, 181, SECTOR_DEG))[0] / len(t)
    return float(share.max()), int((share < 0.02).sum()), float(np.nanmedian(gaps))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("campaign", type=Path)
    ap.add_argument("--strategies", required=True)
    ap.add_argument("--seeds", default="700-707")
    ap.add_argument("--episodes", type=int, default=1500)
    args = ap.parse_args()
    print(f"First {args.episodes} episodes, means over seeds {args.seeds}.")
    print("| strategy | largest sector share of goal targets | sectors under 2% | goal to nearest "
          "outcome / outcome spread (median) |")  # fmt: skip
    print("|---|---|---|---|")
    for strat in args.strategies.split(","):
        rows = np.array([run_targets(args.campaign / strat / f"seed-{s}", args.episodes)
                         for s in parse_seeds(args.seeds)])  # fmt: skip
        print(f"| {strat} | {rows[:, 0].mean():.2f} | {rows[:, 1].mean():.1f} | "
              f"{rows[:, 2].mean():.2f} |")  # fmt: skip


if __name__ == "__main__":
    main()
