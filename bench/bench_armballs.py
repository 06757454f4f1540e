"""Whole ArmBalls / Arm-2-Balls episodes per second (motor primitive, 50 steps, outcome image).

Three ways an episode is played: one at a time with the 64 x 64 outcome image (what a goal
exploration strategy with a learned goal space needs), one at a time without the image (an
engineered goal space), and in batches without images (random parameter exploration). Each is
timed over ``--episodes`` episodes, best of ``--repeats``; the machine's other load is not
controlled, so run it on a quiet machine for the figure that matters.

    .venv/bin/python bench/bench_armballs.py [--episodes 3000] [--repeats 3] [--batch 1000]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from sim.armballs import ARM_2_BALLS, ARM_BALLS, ArmBallsEnv


def _best(fn, repeats: int) -> float:
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--episodes", type=int, default=3000)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--batch", type=int, default=1000)
    args = ap.parse_args()
    n = args.episodes
    for name, cfg in (("arm2balls", ARM_2_BALLS), ("armballs", ARM_BALLS)):
        env = ArmBallsEnv(cfg)
        params = np.random.default_rng(0).uniform(-1.0, 1.0, (n, env.n_params))

        def single(render: bool, env: ArmBallsEnv = env, params: np.ndarray = params) -> None:
            rng = np.random.default_rng(1)
            for p in params:
                env.play(p, rng, render=render)

        def batched(env: ArmBallsEnv = env, params: np.ndarray = params) -> None:
            rng = np.random.default_rng(1)
            for i in range(0, n, args.batch):
                env.play_batch(params[i : i + args.batch], rng)

        with_image = n / _best(lambda: single(True), args.repeats)
        without = n / _best(lambda: single(False), args.repeats)
        batch = n / _best(batched, args.repeats)
        print(
            f"{name:>9}: {with_image:8.0f} episodes/s one at a time with the image, "
            f"{without:8.0f} without, {batch:8.0f} in batches of {args.batch}"
        )


if __name__ == "__main__":
    main()
