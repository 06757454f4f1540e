"""Campaign wall time with the ``local`` backend against ``ray`` on this machine.

Not a test: it runs the same campaign (default 2 strategies x 4 seeds x 500 twin episodes, 2 at
a time) twice, in fresh folders: with ``--backend local`` (spawned processes) and with
``--backend ray`` (a Ray instance started here on 127.0.0.1 with 2 CPUs). It prints:

- the wall time of each campaign (s) and their ratio ray / local (scheduling overhead);
- the time to start the local Ray instance (s), counted apart from the campaign;
- per trial, the slot-seconds spent outside trials: (wall x slots - sum of the trials' own
  wall times) / trials, for each backend; the difference is Ray's overhead per trial (s);
- whether the per-seed results (every episode's metrics) are the same on both backends, and
  whether the code on disk changed meanwhile (then they may differ for that reason alone).

Usage:
    .venv/bin/python bench/bench_ray.py [--episodes 500] [--seeds 0,1,2,3]
        [--strategies rpe,rge-efr] [--jobs 2] [--out DIR] [--keep]

A campaign costs about 0.1 s of CPU per episode (docs/goal_exploration.md): the default is
8 x 500 x 0.1 = 400 s of CPU per backend, 200 s of wall on 2 free cores; more when the machine
is shared (the load average is printed before and after).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from explore.campaigns.plan import run_campaign
from explore.campaigns.ray_backend import LOCAL_OBJECT_STORE_BYTES, import_ray
from explore.runs.layout import METRICS_FILE, TRIAL_FILE


def trial_walls(out: Path, strategies: list[str], seeds: list[int]) -> list[float]:
    """Each trial's own wall time (s), from its ``trial.json``."""
    walls = []
    for s in strategies:
        for seed in seeds:
            info = json.loads((out / s / f"seed-{seed}" / TRIAL_FILE).read_text())
            walls.append(info["finished"] - info["started"])
    return walls


def code_digest() -> str:
    """SHA-256 of the project's code and models, to tell whether they changed during the
    bench (workers started later import what is on disk then)."""
    root = Path(__file__).resolve().parents[1]
    h = hashlib.sha256()
    for pkg in ("robot", "sim", "vision", "calibration", "explore"):
        for f in sorted((root / pkg).rglob("*")):
            if f.suffix in (".py", ".xml", ".eds") and f.is_file():
                h.update(str(f.relative_to(root)).encode() + b"\0" + f.read_bytes())
    return h.hexdigest()


def same_runs(a: Path, b: Path, strategies: list[str], seeds: list[int]) -> bool:
    """Whether every run's metrics.csv is the same in both campaigns."""
    return all(
        (a / s / f"seed-{seed}" / METRICS_FILE).read_bytes()
        == (b / s / f"seed-{seed}" / METRICS_FILE).read_bytes()
        for s in strategies
        for seed in seeds
    )


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--episodes", type=int, default=500)
    p.add_argument("--seeds", default="0,1,2,3")
    p.add_argument("--strategies", default="rpe,rge-efr")
    p.add_argument("--bootstrap", type=int, default=100, help="random episodes first (paper 100)")
    p.add_argument("--jobs", type=int, default=2, help="trials at once on either backend")
    p.add_argument("--out", type=Path, default=None, help="where the campaigns go (default tmp)")
    p.add_argument("--keep", action="store_true", help="keep the campaign folders")
    args = p.parse_args()
    strategies = args.strategies.split(",")
    seeds = [int(s) for s in args.seeds.split(",")]
    n = len(strategies) * len(seeds)
    root = args.out or Path(tempfile.mkdtemp(prefix="bench_ray_"))
    root.mkdir(parents=True, exist_ok=True)
    for name in ("local", "ray"):
        if (root / name).exists():
            shutil.rmtree(root / name)
    opts = {"bootstrap": args.bootstrap}
    digest = code_digest()
    print(f"{n} trials ({args.strategies} x seeds {args.seeds}) x {args.episodes} twin episodes, "
          f"{args.jobs} at a time; {os.cpu_count()} CPUs; load average before "
          f"{os.getloadavg()[0]:.1f}")  # fmt: skip

    t0 = time.perf_counter()
    run_campaign(root / "local", strategies, seeds, args.episodes, args.jobs, options=opts)
    wall = {"local": time.perf_counter() - t0}

    ray = import_ray(local=True)
    t0 = time.perf_counter()
    ray.init(address="local", num_cpus=args.jobs, include_dashboard=False,
             object_store_memory=LOCAL_OBJECT_STORE_BYTES)  # fmt: skip
    ray_start = time.perf_counter() - t0
    t0 = time.perf_counter()
    run_campaign(root / "ray", strategies, seeds, args.episodes, options=opts, backend="ray")
    wall["ray"] = time.perf_counter() - t0
    ray.shutdown()

    print(f"load average after {os.getloadavg()[0]:.1f}")
    outside = {}
    for name in ("local", "ray"):
        walls = trial_walls(root / name, strategies, seeds)
        outside[name] = (wall[name] * args.jobs - sum(walls)) / n
        print(f"{name:>5}: campaign {wall[name]:7.1f} s wall; trials {sum(walls):7.1f} s "
              f"(mean {sum(walls) / n:.1f} s); outside trials {outside[name]:.2f} "
              "slot-s per trial")  # fmt: skip
    print(f"Ray instance start: {ray_start:.1f} s (not in the ray campaign's wall time)")
    print(f"ray / local wall time: {wall['ray'] / wall['local']:.3f}")
    print(f"Ray overhead per trial: {outside['ray'] - outside['local']:+.2f} s "
          "(slot-seconds outside trials, ray minus local)")  # fmt: skip
    same = same_runs(root / "local", root / "ray", strategies, seeds)
    print(f"same per-seed results on both backends: {'yes' if same else 'NO'}")
    if code_digest() != digest:
        print("the code changed on disk during the bench: the backends may have run different "
              "code (run it on a copy of the tree that nobody edits)")  # fmt: skip
    if not args.keep and args.out is None:
        shutil.rmtree(root)
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
