"""The Arm-2-Balls comparison against the published campaign (docs/results_armballs.md): the
exploration ratio of every run of a campaign folder at the published checkpoints, the table of
ours beside the published one, the curves against iterations as in the published figures, and
MGE's interest per module.

The exploration ratio after n episodes is the fraction of the 30 x 30 cells of [-1, 1]^2 that
hold the final ball position of one of the first n episodes, bootstrap included, at
n = int(i * 10000 / 30) (``explore.runs.metrics.exploration_ratio``; the published values:
docs/armballs_published.csv). Interest is rebuilt by replaying each MGE run's history through
its own strategy (``experiments/distractor_figures.py``), and each module named by what it follows.

    .venv/bin/python experiments/armballs_results.py CAMPAIGN [--out docs/img] [--prefix armballs]

Prints the Markdown table (mean +- sd over seeds, ddof 1; the published mean +- sd over its
runs; |ours - published| in published sd; Welch's p) and the campaign's wall time from the runs'
trial.json, and writes PREFIX_curves.png, PREFIX_interest.png and PREFIX_scatter.png; with the
interest, the share of MGE-EFR's goals in the distractor's module per 1000 episodes.
"""

from __future__ import annotations

import argparse
import csv
import json
from pathlib import Path

import numpy as np
from script_helpers import save_figure  # experiments/script_helpers.py, beside this script

from explore.runs.layout import METRICS_FILE
from explore.runs.metrics import checkpoints, exploration_ratio, read_metrics

ROOT = Path(__file__).resolve().parents[1]
PUBLISHED = ROOT / "docs" / "armballs_published.csv"
PUBLISHED_RUNS = ROOT / "docs" / "armballs_published_runs.csv"
# our strategy -> the published algorithm (the spatial autoencoder has no published row)
NAMES = {
    "rpe": "RPE", "rge-efr": "RGE-EFR", "mge-efr": "MGE-EFR", "rge-vae": "RGE-VAE",
    "mge-vae": "MGE-VAE", "rge-betavae": "RGE-betaVAE", "mge-betavae": "MGE-betaVAE",
}  # fmt: skip
ORDER = ("mge-efr", "mge-betavae", "rge-betavae", "rge-efr", "rge-vae", "mge-vae", "rpe",
         "mge-sae", "rge-sae")  # the published table's order, then ours  # fmt: skip
TABLE_AT = (1000, 3000, 5000, 9666)


def campaign_ratios(campaign: Path) -> dict[str, np.ndarray]:
    """strategy -> exploration ratio (seeds, 30 checkpoints) of the campaign's runs."""
    out = {}
    for folder in sorted(p for p in campaign.iterdir() if p.is_dir()):
        rows = []
        for run in sorted(folder.glob("seed-*"), key=lambda p: int(p.name.split("-")[1])):
            if (run / METRICS_FILE).exists():
                cells = read_metrics(run / METRICS_FILE)["ball_cells"]
                rows.append(exploration_ratio(cells, checkpoints()))
        if rows:
            out[folder.name] = np.array(rows)
    return out


def published() -> dict[str, dict[int, tuple[int, float, float]]]:
    """algorithm -> iterations -> (runs, mean, sd) of the published campaign."""
    table: dict[str, dict[int, tuple[int, float, float]]] = {}
    with open(PUBLISHED, newline="") as f:
        for row in csv.DictReader(f):
            table.setdefault(row["algorithm"], {})[int(row["iterations"])] = (
                int(row["runs"]), float(row["mean"]), float(row["sd"])
            )  # fmt: skip
    return table


def published_runs() -> dict[str, dict[int, np.ndarray]]:
    """algorithm -> iterations -> the published runs' ratios (distinct runs: RGE-EFR's pairs
    of identical runs once, docs/armballs.md)."""
    runs: dict[str, dict[int, dict[tuple[str, str], float]]] = {}
    with open(PUBLISHED_RUNS, newline="") as f:
        for row in csv.DictReader(f):
            key = (row["seed"], row["distract_noise"]) if row["algorithm"] == "RGE-EFR" else (
                row["run"], "")  # fmt: skip
            by_it = runs.setdefault(row["algorithm"], {}).setdefault(int(row["iterations"]), {})
            by_it[key] = float(row["exploration_30"])
    return {a: {i: np.array(list(v.values())) for i, v in d.items()} for a, d in runs.items()}


def sd(a: np.ndarray) -> float:
    return float(np.std(a, ddof=1)) if len(a) > 1 else 0.0


def table(ratios: dict[str, np.ndarray]) -> str:
    """The Markdown table of ours beside the published, at ``TABLE_AT``."""
    from scipy import stats

    pub, pub_runs = published(), published_runs()
    idx = {int(n): i for i, n in enumerate(checkpoints())}
    head = "| strategy | runs (ours / published) | " + " | ".join(
        f"{n}: ours | published | gap (sd) | Welch p" for n in TABLE_AT
    ) + " |"  # fmt: skip
    lines = [head, "|" + "---|" * (2 + 4 * len(TABLE_AT))]
    for name in [s for s in ORDER if s in ratios]:
        r = ratios[name]
        alg = NAMES.get(name)
        p = pub.get(alg or "", {})
        runs = f"{len(r)} / {p[TABLE_AT[0]][0] if p else '-'}"
        cells = []
        for n in TABLE_AT:
            ours = r[:, idx[n]]
            ours_txt = f"{ours.mean():.3f} ± {sd(ours):.3f}"
            if not p:
                cells += [ours_txt, "-", "-", "-"]
                continue
            _, m, s = p[n]
            others = pub_runs[alg][n]
            t = stats.ttest_ind(ours, others, equal_var=False)
            cells += [ours_txt, f"{m:.3f} ± {s:.3f}", f"{abs(ours.mean() - m) / s:.1f}",
                      f"{t.pvalue:.2g}"]  # fmt: skip
        lines.append(f"| {name} | {runs} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def curves_figure(ratios: dict[str, np.ndarray], out: Path) -> Path:
    """Exploration ratio against iterations: ours (solid, +-1 sd shaded) beside the published
    (dashed, +-1 sd dotted, drawn whether or not the campaign ran the strategy), one panel for
    the engineered strategies, one for the learned."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    pub = published()
    x = checkpoints()
    panels = (("engineered features and RPE", ("rpe", "rge-efr", "mge-efr")),
              ("learned goal spaces", ("rge-vae", "mge-vae", "rge-betavae", "mge-betavae",
                                       "rge-sae", "mge-sae")))  # fmt: skip
    fig, axes = plt.subplots(1, 2, figsize=(13, 5), sharey=True)
    for ax, (title, names) in zip(axes, panels, strict=True):
        for k, name in enumerate(n for n in names if n in ratios or NAMES.get(n) in pub):
            color = f"C{k}"
            if name in ratios:
                r = ratios[name]
                mean, s = r.mean(axis=0), r.std(axis=0, ddof=1) if len(r) > 1 else 0 * r[0]
                ax.plot(x, mean, color=color, lw=2, label=f"{name} (ours, {len(r)} seeds)")
                ax.fill_between(x, mean - s, mean + s, color=color, alpha=0.15)
            alg = NAMES.get(name)
            if alg in pub:
                pm = np.array([pub[alg][n][1] for n in x])
                ps = np.array([pub[alg][n][2] for n in x])
                runs = pub[alg][int(x[-1])][0]
                ax.plot(x, pm, color=color, ls="--", lw=1.5, label=f"{alg} (published, {runs})")
                ax.plot(x, pm - ps, color=color, ls=":", lw=0.8)
                ax.plot(x, pm + ps, color=color, ls=":", lw=0.8)
        if not any(n in ratios for n in names):
            title += " (published only: not run here)"
        ax.set_title(f"Arm-2-Balls, {title}")
        ax.set_xlabel("iterations (episodes, bootstrap included)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8, loc="upper left")
    axes[0].set_ylabel("exploration ratio (30 x 30 cells of [-1, 1]^2)")
    fig.tight_layout()
    save_figure(fig, out)
    return out


def interest_figure(campaign: Path, out: Path) -> Path | None:
    """MGE's interest per module over the episodes, mean over seeds, modules named by what
    they follow."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from distractor_figures import interests_over_time

    mge = [s for s in ORDER if s.startswith("mge-") and (campaign / s).is_dir()]
    if not mge:
        return None
    fig, axes = plt.subplots(1, len(mge), figsize=(5.2 * len(mge), 4.2), squeeze=False)
    for ax, name in zip(axes[0], mge, strict=True):
        curves: dict[str, list[np.ndarray]] = {}
        for run in sorted((campaign / name).glob("seed-*")):
            interest, names = interests_over_time(run)
            for k, label in enumerate(names):
                key = label.split(" (R²")[0].split(": ")[-1]  # the object a module follows
                curves.setdefault(key, []).append(interest[:, k])
        for label, runs in sorted(curves.items()):
            n = min(len(r) for r in runs)
            mean = np.mean([r[:n] for r in runs], axis=0)
            ax.plot(np.arange(1, n + 1), mean, label=f"{label} ({len(runs)} module-runs)")
        ax.set_title(f"{name}: interest per module (mean)", fontsize=10)
        ax.set_xlabel("episode")
        ax.set_yscale("log")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    axes[0][0].set_ylabel("interest |exponential average of progress|")
    fig.tight_layout()
    save_figure(fig, out)
    return out


def distractor_goal_share(campaign: Path, window: int = 1000) -> str:
    """The share of MGE-EFR's episodes whose goal was in the distractor's module (module 1:
    ``EngineeredGoalSpace`` puts the ball's module first), per ``window`` episodes, mean over
    the runs, as a Markdown table; then each run's row."""
    from explore.runs.store import iter_history

    rows, names = [], []
    for run in sorted((campaign / "mge-efr").glob("seed-*")):
        episode, module = np.array([(r.episode, r.module) for r in iter_history(run)]).T
        row = []
        for a in range(0, int(episode.max()) + 1, window):
            chosen = module[(episode >= a) & (episode < a + window) & (module >= 0)]
            row.append(float(np.mean(chosen == 1)) if len(chosen) else np.nan)
        rows.append(row)
        names.append(run.name)
    if not rows:
        return ""
    n = min(len(r) for r in rows)
    table = np.array([r[:n] for r in rows])
    head = "| episodes | " + " | ".join(f"{k * window}-{(k + 1) * window - 1}" for k in range(n))
    lines = [head + " |", "|---" * (n + 1) + "|"]
    lines.append("| goals in the distractor's module (mean) | "
                 + " | ".join(f"{v:.3f}" for v in np.nanmean(table, axis=0)) + " |")  # fmt: skip
    lines += [f"| {name} | " + " | ".join(f"{v:.2f}" for v in row) + " |"
              for name, row in zip(names, table, strict=True)]  # fmt: skip
    return "\n".join(lines)


def scatter_figure(campaign: Path, out: Path, seed: int | None = None) -> Path:
    """Final ball positions of one seed's run per strategy (the published appendix's
    scatter plots), with the number of episodes that caught the ball; ``seed``: the campaign's
    lowest seed when None."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from explore.runs.store import iter_history

    if seed is None:
        seed = min(int(p.name.split("-")[1]) for p in campaign.glob("*/seed-*"))
    names = [s for s in ORDER if (campaign / s / f"seed-{seed}").is_dir()]
    fig, axes = plt.subplots(2, (len(names) + 1) // 2, figsize=(3.3 * ((len(names) + 1) // 2),
                             6.8), squeeze=False)  # fmt: skip
    for ax in axes.ravel()[len(names) :]:
        ax.set_visible(False)
    for ax, name in zip(axes.ravel(), names, strict=False):
        recs = list(iter_history(campaign / name / f"seed-{seed}"))
        ball = np.array([r.ball for r in recs])
        caught = np.array([r.ball_moved for r in recs])
        cells = read_metrics(campaign / name / f"seed-{seed}" / METRICS_FILE)["ball_cells"][-1]
        ax.scatter(ball[caught, 0], ball[caught, 1], s=1.5, alpha=0.4)
        ax.set_title(f"{name}: {cells / 900:.2f}, caught {int(caught.sum())}", fontsize=9)
        ax.set_xlim(-1, 1)
        ax.set_ylim(-1, 1)
        ax.set_aspect("equal")
        ax.tick_params(labelsize=7)
    fig.suptitle(f"Final ball positions, seed {seed}, {len(recs)} episodes:\nexploration ratio "
                 "and episodes that caught the ball", fontsize=10)  # fmt: skip
    fig.tight_layout()
    save_figure(fig, out)
    return out


def wall_times(campaign: Path) -> dict[str, float]:
    """From the runs' trial.json: the span from the first start to the last end, s, and the
    sum of the trials' own durations, s (the last session of each run)."""
    starts, ends, total = [], [], 0.0
    for path in campaign.glob("*/seed-*/trial.json"):
        t = json.loads(path.read_text())
        if "finished" in t:
            starts.append(t["started"])
            ends.append(t["finished"])
            total += t["finished"] - t["started"]
    if not starts:
        return {}
    return {"span_s": max(ends) - min(starts), "trials_s": total, "trials": len(starts)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("campaign", type=Path)
    ap.add_argument("--out", type=Path, default=Path("docs/img"))
    ap.add_argument("--prefix", default="armballs")
    ap.add_argument("--no-interest", action="store_true", help="skip the interest figure")
    args = ap.parse_args()
    ratios = campaign_ratios(args.campaign)
    print(table(ratios))
    print()
    print(json.dumps(wall_times(args.campaign)))
    args.out.mkdir(parents=True, exist_ok=True)
    curves_figure(ratios, args.out / f"{args.prefix}_curves.png")
    scatter_figure(args.campaign, args.out / f"{args.prefix}_scatter.png")
    if not args.no_interest:
        interest_figure(args.campaign, args.out / f"{args.prefix}_interest.png")
        print(distractor_goal_share(args.campaign))


if __name__ == "__main__":
    main()
