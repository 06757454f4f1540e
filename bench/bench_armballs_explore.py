"""Exploration speed on the Arm-2-Balls rig: iterations (episodes) per second of each strategy,
the whole loop (propose, simulate, render, store, learn, count), with the published preset.

The latent strategies' speed does not depend on what their representation learnt, so without
``--vae``/``--sae`` they run on untrained models of the project's architectures. Each figure is
the best of ``--repeats`` runs of ``--episodes`` episodes (the bootstrap included, as in a
campaign), in wall time and in this process's CPU time (``time.process_time``: what the loop
costs whatever else the machine runs; a campaign of S strategies x 8 seeds x 10,000 episodes
takes about the sum of their CPU times divided by the cores it gets).

    .venv/bin/python bench/bench_armballs_explore.py [--episodes 2000] [--repeats 2]
        [--strategies rpe,rge-efr,...] [--vae DIR] [--sae DIR]
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # testkit/, not installed
from testkit.untrained_models import save_untrained_models

STRATEGIES = ("rpe", "rge-efr", "mge-efr", "rge-vae", "mge-vae", "rge-sae", "mge-sae")


def one_run(out: Path, strategy: str, episodes: int, models: dict[str, str]) -> tuple[float, float]:
    """(wall s, CPU s) of one run of ``episodes`` on arm2balls with the corl2018 preset."""
    from explore.campaigns.trial import Trial, run_trial
    from explore.learner.strategies.registry import preset_options

    opts = preset_options("corl2018", strategy)
    if "vae" in strategy:
        opts["vae"] = models["vae"]
    if "sae" in strategy:
        opts["sae"] = models["sae"]
    shutil.rmtree(out, ignore_errors=True)
    rig = {"name": "arm2balls", "rig_id": "twin", "options": {}}
    wall, cpu = time.perf_counter(), time.process_time()
    run_trial(Trial.of(str(out), strategy, 0, episodes, opts, rig))
    return time.perf_counter() - wall, time.process_time() - cpu


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--episodes", type=int, default=2000)
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--strategies", default=",".join(STRATEGIES))
    ap.add_argument("--vae", help="a trained VAE folder (default: an untrained one)")
    ap.add_argument("--sae", help="a trained spatial autoencoder (default: an untrained one)")
    args = ap.parse_args()
    from vision.vae import limit_threads

    limit_threads(1)  # a campaign worker's share: one core each
    with tempfile.TemporaryDirectory(prefix="bench-armballs-") as tmp:
        root = Path(tmp)
        models = save_untrained_models(root)
        models.update({k: v for k, v in (("vae", args.vae), ("sae", args.sae)) if v})
        print(f"{'strategy':<12} {'episodes':>8} {'wall it/s':>10} {'CPU it/s':>9} "
              f"{'CPU ms/it':>9}")  # fmt: skip
        for name in args.strategies.split(","):
            runs = [one_run(root / "run", name, args.episodes, models) for _ in range(args.repeats)]
            wall = min(w for w, _ in runs)
            cpu = min(c for _, c in runs)
            print(f"{name:<12} {args.episodes:>8} {args.episodes / wall:>10.0f} "
                  f"{args.episodes / cpu:>9.0f} {1e3 * cpu / args.episodes:>9.2f}")  # fmt: skip


if __name__ == "__main__":
    main()
