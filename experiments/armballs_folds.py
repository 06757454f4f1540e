"""Arm-2-Balls MGE-EFR runs confined by a folded arm: per-run figures of campaign folders, the
original campaign's bootstraps rebuilt, and how often a bootstrap starts folded
(docs/results_armballs_stalls.md, "Runs confined by a folded arm").

The joint command is clip(sum_k basis_k(t) p_jk, -1, 1) and the angle pi x the command
(docs/armballs.md, "Motor primitive"), so a joint whose unclipped final command is at least 1
in magnitude ends at angle pi (folded back, or for joint 0 the first link pointing to -x), and
small changes of its parameters change nothing while the sum stays beyond 1. With the link
lengths 0.3, 0.2, 0.2, 0.1, 0.1, 0.05, 0.05 that confines where the hand, and a caught ball,
can end: joint 0 at pi puts the first link's end at (-0.3, 0), so x <= -0.3 + 0.7 = 0.4;
joint 1 or 2 at pi caps the distance from the base at |0.3 - 0.2| + 0.5 = |0.5 - 0.2| + 0.3 =
0.6; joint 3 or 4 caps it at 0.8, joint 5 or 6 at 0.9 (the same sums further out).

For every run of ``CAMPAIGN/mge-efr/seed-*``:
- the bootstrap episodes that caught the ball, and how many of them ended with joint 0, 1 or 2
  folded;
- the ball-moving episodes of 3000-9999: the largest final x of the ball and its largest
  distance from the base, the share that ended with joint 0 folded and with joint 1 or 2, and
  the joint most often folded there with its share;
- the exploration ratio at 9666 (the published last checkpoint).

``--original``: the original campaign's bootstrap parameters of seeds 0-14 rebuilt (its
``mge_efr.py`` seeds numpy's global generator with the seed; each bootstrap episode draws 49
uniform parameters, then the distractor's 50 steps draw 2 normals each), played through our
environment, beside the published runs of those seeds (docs/armballs_published_runs.csv).
``--monte-carlo N``: N random bootstraps of 100 episodes, the share whose catches all ended
folded. ``--figure PNG --seeds 700,702,...``: the final ball positions of those runs' ball moves
of 3000-9999 (the first campaign's runs), with the 0.6 circle and the line x = 0.4.

    .venv/bin/python experiments/armballs_folds.py CAMPAIGN [CAMPAIGN ...] [--original]
        [--monte-carlo 2000] [--figure PNG --seeds 700,701,702,704]
"""

from __future__ import annotations

import argparse
import csv
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from explore.runs.layout import METRICS_FILE
from plumbing.cli_errors import error

ROOT = Path(__file__).resolve().parents[1]
PUBLISHED_RUNS = ROOT / "docs" / "armballs_published_runs.csv"
BOOTSTRAP = 100  # the corl2018 preset's engineered bootstrap (column n_bootstrap)
LATE = 3000  # episodes from here on: where the stalled runs' coverage had flattened
FOLD_JOINTS = (0, 1, 2)  # the three longest links' joints (module doc: what a fold confines)
ORIGINAL_SEEDS = range(15)  # the published MGE-EFR seeds (docs/armballs.md)
N_STEPS = 50  # steps per episode; the original's distractor draws 2 normals per step
N_PARAMS = 49


def final_commands(theta: np.ndarray) -> np.ndarray:
    """Unclipped command of each joint at the last step, shape (N, 7), from parameters of shape
    (N, 49) (joint-major, as ``RbfPrimitive``)."""
    from sim.armballs import ARM_2_BALLS
    from sim.armballs.primitives import rbf_basis

    c = ARM_2_BALLS
    last = rbf_basis(c.n_steps, c.n_rbf, c.rbf_sdev)[-1]  # (n_rbf,)
    n_joints = len(c.link_lengths)
    return np.asarray(theta, float).reshape(-1, n_joints, c.n_rbf) @ last


def folded(theta: np.ndarray, joints: tuple[int, ...] = FOLD_JOINTS) -> np.ndarray:
    """Whether each episode ends with one of ``joints`` at angle pi (unclipped final command of
    magnitude >= 1), shape (N,) bool, from parameters of shape (N, 49)."""
    return (np.abs(final_commands(theta)[:, list(joints)]) >= 1.0).any(axis=1)


@dataclass
class RunFolds:
    """One run's figures (episodes counted from 0; distances in the arena's units)."""

    seed: int
    bootstrap_catches: int
    bootstrap_folded: int  # of those, ending with joint 0, 1 or 2 folded
    late_moves: int  # ball-moving episodes from LATE on
    late_x: float  # largest final x of the ball among them
    late_reach: float  # largest final distance of the ball from the base among them
    late_folded_0: float  # share of them ending with joint 0 folded
    late_folded_12: float  # share of them ending with joint 1 or 2 folded
    late_top_joint: int  # the joint most often folded among them (-1: no late move)
    late_top_share: float  # its share
    ratio_9666: float


def run_folds(run: Path) -> RunFolds:
    """The figures of one run folder (its history and metrics.csv)."""
    from explore.runs.store import iter_history

    episode, theta, ball, moved = [], [], [], []
    for r in iter_history(run):
        episode.append(r.episode)
        theta.append(r.theta)
        ball.append(r.ball[:2])
        moved.append(bool(r.ball_moved))
    e, th, b, mv = np.array(episode), np.array(theta), np.array(ball), np.array(moved)
    fold = folded(th)
    boot = mv & (e < BOOTSTRAP)
    late = mv & (e >= LATE)
    nan = float("nan")
    per_joint = (np.abs(final_commands(th[late])) >= 1.0).mean(axis=0) if late.any() else None
    return RunFolds(
        seed=int(run.name.split("-")[1]),
        bootstrap_catches=int(boot.sum()),
        bootstrap_folded=int((boot & fold).sum()),
        late_moves=int(late.sum()),
        late_x=float(b[late, 0].max()) if late.any() else nan,
        late_reach=float(np.linalg.norm(b[late], axis=1).max()) if late.any() else nan,
        late_folded_0=float(folded(th[late], (0,)).mean()) if late.any() else nan,
        late_folded_12=float(folded(th[late], (1, 2)).mean()) if late.any() else nan,
        late_top_joint=-1 if per_joint is None else int(np.argmax(per_joint)),
        late_top_share=nan if per_joint is None else float(per_joint.max()),
        ratio_9666=ratio_at_9666(run),
    )


def ratio_at_9666(run: Path) -> float:
    """The run's exploration ratio at 9666 iterations, from its metrics.csv alone."""
    from explore.runs.metrics import exploration_ratio, read_metrics

    cells = read_metrics(run / METRICS_FILE)["ball_cells"]
    return float(exploration_ratio(cells, np.array([9666]))[0])


def runs_table(runs: list[RunFolds]) -> str:
    lines = [
        "| seed | bootstrap catches | of which folded | ball moves 3000-9999 | their largest x | "
        "their largest distance | share with joint 0 folded | with joint 1 or 2 | "
        "joint most folded (share) | at 9666 |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in runs:
        lines.append(
            f"| {r.seed} | {r.bootstrap_catches} | {r.bootstrap_folded} | {r.late_moves} | "
            f"{r.late_x:.2f} | {r.late_reach:.2f} | {r.late_folded_0:.2f} | "
            f"{r.late_folded_12:.2f} | {r.late_top_joint} ({r.late_top_share:.2f}) | "
            f"{r.ratio_9666:.3f} |"
        )
    return "\n".join(lines)


def original_bootstrap(seed: int) -> np.ndarray:
    """The original campaign's bootstrap parameters for ``seed``, shape (100, 49): numpy's
    legacy generator seeded with it, 49 uniform draws in [-1, 1] per episode followed by the
    distractor's 2 x 50 normal draws (``RandomParameterizationExploration.act`` and
    ``ArmBalls.act`` of the original)."""
    rs = np.random.RandomState(seed)
    out = np.empty((BOOTSTRAP, N_PARAMS))
    for i in range(BOOTSTRAP):
        out[i] = rs.uniform(low=-np.ones(N_PARAMS), high=np.ones(N_PARAMS))
        for _ in range(N_STEPS):
            rs.randn(2)
    return out


def published_at(iterations: int) -> dict[int, list[float]]:
    """seed -> the published MGE-EFR runs' exploration ratios at ``iterations`` (win_size 500
    then 1000)."""
    out: dict[int, list[float]] = {}
    with open(PUBLISHED_RUNS, newline="") as f:
        for row in csv.DictReader(f):
            if row["algorithm"] == "MGE-EFR" and int(row["iterations"]) == iterations:
                out.setdefault(int(row["seed"]), []).append(float(row["exploration_30"]))
    return out


def original_table() -> str:
    """The original's bootstraps of seeds 0-14 played here, beside the published runs."""
    from sim.armballs import ARM_2_BALLS, ArmBallsEnv

    env = ArmBallsEnv(ARM_2_BALLS)
    pub = published_at(9666)
    lines = [
        "| seed | bootstrap catches (episode) | folded | final distance of the ball | "
        "published at 9666 (win 500, 1000) |",
        "|---|---|---|---|---|",
    ]
    for seed in ORIGINAL_SEEDS:
        theta = original_bootstrap(seed)
        paths = env.play_batch(theta, np.random.default_rng(0))  # the ball needs no draws
        caught = np.flatnonzero(paths.catch_step >= 0)
        fold = folded(theta[caught])
        dist = np.linalg.norm(paths.ball[caught, -1], axis=1)
        lines.append(
            f"| {seed} | {len(caught)} ({', '.join(map(str, caught))}) | {int(fold.sum())} | "
            f"{', '.join(f'{d:.2f}' for d in dist)} | "
            f"{', '.join(f'{v:.3f}' for v in pub.get(seed, []))} |"
        )
    return "\n".join(lines)


def monte_carlo(n: int, seed: int = 12345) -> str:
    """Shares over ``n`` random bootstraps of 100 episodes: no catch, every catch folded."""
    from sim.armballs import ARM_2_BALLS, ArmBallsEnv

    env = ArmBallsEnv(ARM_2_BALLS)
    rng = np.random.default_rng(seed)
    theta = rng.uniform(-1.0, 1.0, (n * BOOTSTRAP, N_PARAMS))
    paths = env.play_batch(theta, rng)
    caught = (paths.catch_step >= 0).reshape(n, BOOTSTRAP)
    fold = folded(theta).reshape(n, BOOTSTRAP) & caught
    k = caught.sum(axis=1)
    all_folded = (k > 0) & (fold.sum(axis=1) == k)
    share = fold.sum() / max(caught.sum(), 1)
    return (
        f"{n} random bootstraps of {BOOTSTRAP} (seed {seed}): catch rate {caught.mean():.4f}; "
        f"catches ending folded {share:.3f}; no catch {np.mean(k == 0):.3f}; "
        f"every catch folded {all_folded.mean():.3f} (exactly one catch, folded "
        f"{np.mean(all_folded & (k == 1)):.3f})"
    )


def figure(runs: list[Path], out: Path) -> None:
    """Final ball positions of each run's ball moves of LATE-9999, one panel a run."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from script_helpers import save_figure  # experiments/script_helpers.py, beside this script

    from explore.runs.store import iter_history

    fig, axes = plt.subplots(1, len(runs), figsize=(3.2 * len(runs), 3.4), squeeze=False)
    t = np.linspace(0, 2 * np.pi, 200)
    for ax, run in zip(axes[0], runs, strict=True):
        pts = np.array(
            [r.ball[:2] for r in iter_history(run) if r.ball_moved and r.episode >= LATE]
        )
        if len(pts):
            ax.scatter(pts[:, 0], pts[:, 1], s=1, alpha=0.4)
        ax.plot(np.cos(t), np.sin(t), "k-", lw=0.6)
        ax.plot(0.6 * np.cos(t), 0.6 * np.sin(t), "r--", lw=0.8)
        ax.axvline(0.4, color="tab:orange", ls=":", lw=0.8)
        ax.plot([0.6], [0.6], "k+")
        ax.set_xlim(-1, 1)
        ax.set_ylim(-1, 1)
        ax.set_aspect("equal")
        ax.set_title(f"{run.name}: {ratio_at_9666(run):.3f} at 9666", fontsize=8)
        ax.tick_params(labelsize=6)
    fig.tight_layout()
    save_figure(fig, out)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("campaigns", nargs="*", type=Path, help="campaign folders (mge-efr runs)")
    ap.add_argument("--strategy", default="mge-efr")
    ap.add_argument("--original", action="store_true", help="the original's bootstraps, 0-14")
    ap.add_argument("--monte-carlo", type=int, default=0, metavar="N", help="random bootstraps")
    ap.add_argument("--figure", type=Path, help="PNG of the late ball moves of --seeds")
    ap.add_argument("--seeds", default="", help="comma-separated seeds of the first campaign")
    args = ap.parse_args(argv)
    for c in args.campaigns:
        folder = c / args.strategy
        if not folder.is_dir():
            return error(f"{c} has no {args.strategy}/ folder: give a campaign folder")
        runs = sorted(folder.glob("seed-*"), key=lambda p: int(p.name.split("-")[1]))
        figs = [run_folds(r) for r in runs if (r / METRICS_FILE).exists()]
        print(f"## {c}\n\n{runs_table(figs)}\n")
    if args.original:
        print(f"## the original's bootstraps\n\n{original_table()}\n")
    if args.monte_carlo:
        print(monte_carlo(args.monte_carlo))
    if args.figure:
        if not args.campaigns or not args.seeds:
            return error("--figure needs a campaign folder and --seeds")
        folder = args.campaigns[0] / args.strategy
        figure([folder / f"seed-{int(k)}" for k in args.seeds.split(",")], args.figure)
    return 0


if __name__ == "__main__":
    sys.exit(main())
