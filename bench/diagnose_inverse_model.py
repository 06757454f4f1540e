"""Why does engineered goal exploration (rge-efr) reach fewer or more ball cells than RPE? A look
at its inverse model in a finished run.

For every goal-directed episode k of a run, the nearest stored episode j < k in (context,
outcome) space to (context_k, goal_k) is found again (the 1-NN the meta-policy used, in the
wrap-safe features of explore/goal_spaces.py, before the exploration noise). Prints: how often
that neighbour had moved the ball, how often episode k then moved it (after a moving neighbour
and after a still one), and the mean distance between goal and outcome in goal-space units.

    .venv/bin/python bench/diagnose_inverse_model.py RUN [RUN ...]

Only for runs of the engineered strategies (rge-efr, mge-efr module 0).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from explore.goal_spaces import wrap_safe_features
from explore.store import RunStore


def diagnose(run: Path) -> dict[str, float]:
    """Statistics of one run's goal-directed episodes (fractions in [0, 1])."""
    recs = RunStore.open(run).records
    ctx = np.array([wrap_safe_features(r.context_ball) for r in recs])
    out = np.array([wrap_safe_features(r.ball) for r in recs])
    moved = np.array([r.ball_moved for r in recs])
    points = np.hstack([ctx, out])
    nn_moved, k_moved, errors = [], [], []
    for k, r in enumerate(recs):
        if r.kind not in ("explore", "exploit") or r.module != 0 or k == 0:
            continue
        if r.goal.shape != ctx[k].shape:
            raise SystemExit(f"{run}: goal of shape {r.goal.shape}: not an engineered run")
        query = np.concatenate([ctx[k], r.goal])
        j = int(np.argmin(np.linalg.norm(points[:k] - query, axis=1)))
        nn_moved.append(moved[j])
        k_moved.append(moved[k])
        errors.append(float(np.linalg.norm(out[k] - r.goal)))
    a, b = np.array(nn_moved, dtype=bool), np.array(k_moved, dtype=bool)
    if len(a) == 0:
        raise SystemExit(f"{run}: no goal-directed episode")
    return {
        "goal_episodes": float(len(a)),
        "neighbour_moved": float(a.mean()),
        "moved": float(b.mean()),
        "moved_after_moving_neighbour": float(b[a].mean()) if a.any() else float("nan"),
        "moved_after_still_neighbour": float(b[~a].mean()) if (~a).any() else float("nan"),
        "goal_error": float(np.mean(errors)),
        "moved_all_episodes": float(moved.mean()),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", type=Path, nargs="+")
    args = ap.parse_args()
    for run in args.runs:
        d = diagnose(run)
        print(
            f"{run}: {d['goal_episodes']:.0f} goal episodes; the neighbour had moved the ball in "
            f"{d['neighbour_moved']:.1%}; the ball moved in {d['moved']:.1%} (after a moving "
            f"neighbour {d['moved_after_moving_neighbour']:.1%}, after a still one "
            f"{d['moved_after_still_neighbour']:.1%}); goal error {d['goal_error']:.2f}; "
            f"moved in {d['moved_all_episodes']:.1%} of all episodes"
        )


if __name__ == "__main__":
    main()
