"""Short runs whose fingerprints must not depend on the machine: what
``tests/system/test_determinism.py`` runs in subprocesses under several BLAS kernels, thread
counts and numpy CPU feature sets (``SETTINGS``), against its golden fingerprints.

    python -m testkit.determinism [NAME ...] [--root DIR]   # prints {name: sha256} as JSON

Each run is a few tens of episodes, with a short bootstrap so that most of them are goal
episodes (the nearest-neighbour queries, the interests, the stall count, the goal sampler).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path
from typing import Any

from explore.rigs.rig import RigConfig
from explore.runs.config import RunConfig, StrategyConfig
from explore.runs.open_run import open_run

# name -> (rig, rig options, strategy, strategy options, episodes, seed); development seeds
SHORT_RUNS: dict[str, tuple[str, dict[str, Any], str, dict[str, Any], int, int]] = {
    "twin-rpe": ("sim", {}, "rpe", {}, 24, 3),
    "twin-rge-efr": ("sim", {}, "rge-efr", {"bootstrap": 8}, 40, 3),
    "twin-mge-efr": ("sim", {}, "mge-efr", {"bootstrap": 8}, 40, 4),
    "twin-rge-efr-frontier": (
        "sim",
        {},
        "rge-efr",
        {"bootstrap": 8, "goal_sampling": "frontier"},
        30,
        5,
    ),
    "arm2balls-rge-corl2018": ("arm2balls", {}, "rge-efr", {"bootstrap": 20}, 400, 6),
    "arm2balls-mge-corl2018": ("arm2balls", {}, "mge-efr", {"bootstrap": 20}, 400, 7),
    "armballs-rge-efr-density": (
        "armballs",
        {},
        "rge-efr",
        {"bootstrap": 20, "goal_sampling": "density"},
        300,
        8,
    ),
}


def numpy_simd_targets(widest_only: bool = False) -> str:
    """numpy's CPU dispatch targets this machine has (``NPY_DISABLE_CPU_FEATURES`` turns them
    off: numpy then runs its baseline code), or only the AVX-512 ones."""
    try:
        from numpy._core import _multiarray_umath as umath
    except ImportError:  # numpy 1.x
        from numpy.core import _multiarray_umath as umath  # type: ignore[no-redef]
    have = [f for f in umath.__cpu_dispatch__ if umath.__cpu_features__.get(f)]
    if widest_only:
        have = [f for f in have if "512" in f or f == "X86_V4"]
    return " ".join(have)


# the settings the tests run these under, each an environment beside the default one: the
# BLAS kernel, its thread count, numpy's SIMD code paths
SETTINGS = {
    "prescott-1-thread-no-simd": {
        "OPENBLAS_CORETYPE": "Prescott", "OPENBLAS_NUM_THREADS": "1",
        "NPY_DISABLE_CPU_FEATURES": numpy_simd_targets(),
    },
    "haswell-2-threads": {"OPENBLAS_CORETYPE": "Haswell", "OPENBLAS_NUM_THREADS": "2"},
    "skylakex-no-avx512": {
        "OPENBLAS_CORETYPE": "SkylakeX", "NPY_DISABLE_CPU_FEATURES": numpy_simd_targets(True),
    },
    "zen-2-threads": {"OPENBLAS_CORETYPE": "Zen", "OPENBLAS_NUM_THREADS": "2"},
}  # fmt: skip


def run_config(name: str) -> RunConfig:
    """The config of short run ``name`` (the corl2018 preset where its name says so)."""
    rig, rig_options, strategy, options, episodes, seed = SHORT_RUNS[name]
    if name.endswith("corl2018"):
        from explore.learner.strategies.registry import preset_options

        options = {**preset_options("corl2018", strategy), **options}
    return RunConfig(
        rig=RigConfig(rig, options=dict(rig_options)),
        strategy=StrategyConfig(strategy, dict(options)),
        seed=seed,
        episodes=episodes,
    )


def fingerprint_of(name: str, root: Path) -> str:
    """Run short run ``name`` in ``root/name`` and return its fingerprint."""
    with open_run(root / name, run_config(name), mode="new") as run:
        explorer = run.explore()
    return explorer.fingerprint.hexdigest()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("names", nargs="*", default=list(SHORT_RUNS))
    ap.add_argument("--root", type=Path, default=None, help="where the runs go (default: temp)")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="ergo-determinism-") as tmp:
        root = args.root or Path(tmp)
        out = {name: fingerprint_of(name, root) for name in args.names}
    json.dump(out, sys.stdout, indent=1)
    print()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
