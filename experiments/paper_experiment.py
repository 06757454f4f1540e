"""The paper's experiment on the twin: RPE vs goal exploration (EFR, VAE), several seeds.

Not a test: an experiment that takes minutes to tens of minutes on a CPU. It runs a campaign of
ordinary, resumable run folders (``ergo experiment``), prints the table of final ball cells
(mean +- std over seeds) and each strategy's ratio to RPE (the paper's point: goal exploration
reaches more distinct ball cells than random parameters).

Usage:
    .venv/bin/python experiments/paper_experiment.py --out runs/paper [--episodes 3000]
        [--seeds 0,1,2] [--strategies rpe,rge-efr,mge-efr] [--vae models/vae]
        [--betavae models/betavae] [--jobs 2]

Defaults fit a ~30 min budget on 2 CPU cores: rpe, rge-efr, mge-efr, 3 seeds x 2000 episodes
(~0.12 s of CPU per episode, measured: 9 runs x 240 s / 2 processes = 18 min plus
the shared machine's slowdown). With ``--vae`` and/or
``--betavae`` (``ergo vae train``), rge-vae / mge-betavae are added.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from explore.campaigns.plan import run_campaign
from explore.campaigns.stats import format_table


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", type=Path, default=Path("runs/paper"))
    p.add_argument("--episodes", type=int, default=2000)
    p.add_argument("--seeds", default="0,1,2")
    p.add_argument("--strategies", default=None, help="default: rpe,rge-efr,mge-efr (+ VAE ones)")
    p.add_argument("--vae", type=Path)
    p.add_argument("--betavae", type=Path)
    p.add_argument("--bootstrap", type=int, default=100, help="random episodes first (paper 100)")
    p.add_argument("--jobs", type=int, default=2)
    args = p.parse_args()
    if args.strategies:
        strategies = args.strategies.split(",")
    else:
        strategies = ["rpe", "rge-efr", "mge-efr"]
        if args.vae:
            strategies.append("rge-vae")
        if args.betavae:
            strategies += ["rge-betavae", "mge-betavae"]
    seeds = [int(s) for s in args.seeds.split(",")]
    t0 = time.perf_counter()
    rows = run_campaign(
        args.out, strategies, seeds, args.episodes, args.jobs,
        {"vae": args.vae, "betavae": args.betavae},
        {"bootstrap": args.bootstrap}, progress=False,
    )  # fmt: skip
    print(format_table(rows))
    base = {r["strategy"]: r["cells_mean"] for r in rows}.get("rpe")
    if base:
        for r in rows:
            if r["strategy"] != "rpe":
                print(f"{r['strategy']} / rpe = {r['cells_mean'] / base:.2f}")
    print(f"{time.perf_counter() - t0:.0f} s wall; summary in {args.out / 'summary.csv'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
