"""Runs that move the ball and still cover few cells (issue 31, docs/results.md F10): is the
ball confined to an arc of the ring, and where do the goals aimed beyond it send it?

Per run, over its first ``--episodes`` episodes (histories only):

- the share of episodes that moved the ball, and how many of the ring's 12 sectors of 30
  degrees (angle of the ball's centre about the arm's base) the moved balls entered;
- the largest arc the ball never ended in (degrees, from where to where), and the first
  episode, over the whole run, that ended in its middle third (the arc entered);
- the goal episodes whose goal lies in that arc (the goal's angle in the arena: read from the
  engineered features, or, for a learned space, from an affine map of the ball's (x, y) to the
  code fitted on the run's outcomes, whose residual it prints), and for those: how often the
  ball moved, and how far from the arc the moved balls ended (median, degrees);
- the share of the moved balls that ended off the outer wall (their centre more than 1 cm
  inside the ring's outer limit), the other way a run that moves the ball covers few cells.

    .venv/bin/python experiments/twin_confinement.py RUN [RUN ...] [--episodes 1500]
        [--model DIR] [--figure PNG]

``--model``: the autoencoder folder of learned runs (default: the run's own). ``--figure``: the
ball's angle against the episode, one panel per run (at most 4 runs).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from explore.report.run_data import run_scene
from explore.runs.metrics import CellCounter
from explore.runs.store import RunStore

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # testkit/, not installed
from testkit.inverse_model import goal_space_vectors

SECTOR_DEG = 30.0
OFF_WALL_M = 0.01  # a ball this far inside the ring's outer limit is off the wall (a choice)


def angles_deg(xy: np.ndarray) -> np.ndarray:
    """Angle about the base, degrees in (-180, 180], of (n, 2) positions in metres."""
    return np.degrees(np.arctan2(xy[:, 1], xy[:, 0]))


def largest_gap(angles: np.ndarray) -> tuple[float, float]:
    """(start, width) in degrees of the largest arc of the circle holding none of ``angles``
    (degrees); the arc runs counter-clockwise from start."""
    a = np.sort(np.mod(angles, 360.0))
    gaps = np.diff(np.r_[a, a[0] + 360.0])
    i = int(np.argmax(gaps))
    return float(a[i]), float(gaps[i])


def in_arc(angles: np.ndarray, start: float, width: float) -> np.ndarray:
    """Mask of ``angles`` (degrees) inside the arc (start, start + width)."""
    return np.mod(angles - start, 360.0) < width


def goal_angles(run: Path, recs: list, out: np.ndarray) -> tuple[np.ndarray, str]:
    """Each record's goal as an angle in the arena (degrees, NaN without a goal) and a note on
    how it was read."""
    config = RunStore.read_meta(run)["config"]
    goals = np.full((len(recs), out.shape[1]), np.nan)
    for k, r in enumerate(recs):
        if r.kind in ("explore", "exploit") and np.size(r.goal) == out.shape[1]:
            goals[k] = r.goal
    balls = np.array([np.asarray(r.ball, dtype=float)[:2] for r in recs])
    form = config["strategy"].get("options", {}).get("form")
    if config["strategy"]["name"].endswith("-efr"):
        scene = run_scene(config)
        form = form or scene.default_form
        if form == "polar":
            return np.degrees(np.pi * goals[:, 1]), "polar features"
        if form == "wrap-safe":
            return np.degrees(np.arctan2(goals[:, 2], goals[:, 1])), "wrap-safe features"
        return angles_deg(goals[:, :2]), "cartesian features"
    ok = np.all(np.isfinite(out), axis=1)
    design = np.c_[balls[ok], np.ones(ok.sum())]
    fit, *_ = np.linalg.lstsq(design, out[ok], rcond=None)
    resid = out[ok] - design @ fit
    xy = np.linalg.lstsq(fit[:2].T, (goals - fit[2]).T, rcond=None)[0].T
    note = f"affine code fit, residual sd {np.sqrt((resid**2).mean()):.3f} (code range 2)"
    return angles_deg(xy), note


def describe(run: Path, episodes: int, model: Path | None) -> tuple[str, np.ndarray, tuple]:
    all_recs = RunStore.read(run).records
    recs = all_recs[:episodes]
    scene = run_scene(RunStore.read_meta(run)["config"])
    _, out, _ = goal_space_vectors(run, recs, model)
    balls = np.array([np.asarray(r.ball, dtype=float)[:2] for r in recs])
    moved = np.array([bool(r.ball_moved) for r in recs])
    ang = angles_deg(balls)
    counter = CellCounter(scene.ball_half_width)
    for b in balls:
        counter.add(b)
    sectors = len(set(np.floor(ang[moved] / SECTOR_DEG).astype(int)))
    start, width = largest_gap(ang[moved])
    later = angles_deg(np.array([np.asarray(r.ball, dtype=float)[:2] for r in all_recs]))
    middle = in_arc(later, start + width / 3, width / 3)
    entered = int(np.argmax(middle)) if middle.any() else None
    g_ang, space_note = goal_angles(run, recs, out)
    has_goal = np.isfinite(g_ang)
    aimed = has_goal & in_arc(np.nan_to_num(g_ang), start, width)
    off = np.minimum(np.mod(start - ang, 360.0), np.mod(ang - (start + width), 360.0))
    far_moves = aimed & moved
    off_wall = np.hypot(*balls[moved].T) < scene.ring[1] - OFF_WALL_M
    hi_end = np.mod(start + width + 180.0, 360.0) - 180.0
    lo_end = np.mod(start + 180.0, 360.0) - 180.0
    row = (
        f"| {run} | {counter.count} | {moved.mean():.2f} | {sectors} | {width:.0f} "
        f"({lo_end:.0f} to {hi_end:.0f}) | {entered if entered is not None else 'never'} | "
        f"{aimed.sum()} of {has_goal.sum()} | {moved[aimed].mean() if aimed.any() else 0:.2f} | "
        f"{np.median(off[far_moves]) if far_moves.any() else float('nan'):.0f} | "
        f"{off_wall.mean():.2f} | "
        f"{space_note} |"
    )
    return row, later, (start, width)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", type=Path, nargs="+")
    ap.add_argument("--episodes", type=int, default=1500)
    ap.add_argument("--model", type=Path, help="model folder of learned runs (default: the run's)")
    ap.add_argument("--figure", type=Path, help="ball angle against episode (PNG)")
    args = ap.parse_args()
    print(f"First {args.episodes} episodes. Arc: the largest arc no moved ball ended in "
          "(degrees, counter-clockwise from the first angle to the second).")  # fmt: skip
    print("| run | ball cells | episodes that moved the ball | 30-deg sectors entered (of 12) "
          "| arc never entered | first episode in its middle third | goals aimed into it | "
          "of those, moved the ball | where those balls ended: degrees short of the arc | "
          "moved balls off the wall | goal angle from |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    traces = []
    for run in args.runs:
        row, later, arc = describe(run, args.episodes, args.model)
        print(row)
        traces.append((run, later, arc))
    if args.figure:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        shown = traces[:4]
        fig, axes = plt.subplots(1, len(shown), figsize=(4 * len(shown), 3.4), dpi=100,
                                 sharey=True, squeeze=False)  # fmt: skip
        for ax, (run, later, (start, width)) in zip(axes[0], shown, strict=True):
            ax.plot(np.arange(len(later)), later, ".", ms=1.5, color="k")
            ax.axvline(args.episodes, color="grey", lw=0.8, ls="--")
            for lo in (start - 360.0, start):
                ax.axhspan(lo, lo + width, color="tab:red", alpha=0.12)
            ax.set_ylim(-180, 180)
            ax.set_title(f"{run.parent.name} {run.name}", fontsize=9)
            ax.set_xlabel("episode")
        axes[0][0].set_ylabel("ball angle about the base (deg)")
        fig.tight_layout()
        fig.savefig(args.figure)
        print(f"figure: {args.figure}")


if __name__ == "__main__":
    main()
