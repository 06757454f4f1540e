"""Cost of one training step of the paper's VAE on this machine's CPU (issue 31, step 3).

One step = forward, loss (BCE + beta KL), backward and an Adam update on a batch of 64 images
of 64 x 64 RGB, as ``vision/vae_train.py`` does (the paper's architecture, ``vision/vae.py``).
The cost does not depend on what the images show, so the batch is random pixels. Variants:
torch threads 1 and 2 (this machine has 2 cores), the default (contiguous) memory format
against ``channels_last`` (model and batch), and ``torch.compile`` of the loss (the inductor
backend; reported as failed, with the reason, where it does not work here).

    .venv/bin/python bench/bench_vae_step.py [--steps 40] [--warmup 5] [--batch 64] \
        [--no-compile | --compiled-only]

Prints, per variant: the median wall and CPU milliseconds of a step over ``--steps`` steps after
``--warmup`` (the first compiled steps include compilation, reported apart), and the steps per
second. On a loaded machine the wall figures are what this process got; the CPU figures are
what a step costs.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np
import torch

from vision.vae import Vae, VaeConfig

BATCH = 64  # paper: batch 64
LR = 1e-3  # vision/vae_train.py's default (the cost of a step does not depend on it)


def make_step(model: Vae, compiled: bool):
    """A function x (batch, 3, 64, 64) -> loss that also updates ``model`` with Adam."""
    optim = torch.optim.Adam(model.parameters(), lr=LR)

    def loss_of(x: torch.Tensor) -> torch.Tensor:
        return model.loss(x)["loss"]

    loss_fn = torch.compile(loss_of) if compiled else loss_of

    def step(x: torch.Tensor) -> float:
        optim.zero_grad(set_to_none=True)
        loss = loss_fn(x)
        loss.backward()
        optim.step()
        return float(loss.detach())

    return step


def measure(threads: int, channels_last: bool, compiled: bool, args) -> dict[str, float]:
    torch.set_num_threads(threads)
    torch.manual_seed(0)
    model = Vae(VaeConfig())
    fmt = torch.channels_last if channels_last else torch.contiguous_format
    model = model.to(memory_format=fmt)
    rng = np.random.default_rng(0)
    x = torch.from_numpy(rng.random((args.batch, 3, 64, 64), dtype=np.float32))
    x = x.contiguous(memory_format=fmt)
    step = make_step(model, compiled)
    t0 = time.perf_counter()
    for _ in range(args.warmup):
        step(x)
    warm_s = time.perf_counter() - t0
    wall, cpu = [], []
    for _ in range(args.steps):
        t, c = time.perf_counter(), time.process_time()
        step(x)
        wall.append(time.perf_counter() - t)
        cpu.append(time.process_time() - c)
    return {"wall_ms": 1e3 * float(np.median(wall)), "cpu_ms": 1e3 * float(np.median(cpu)),
            "warmup_s": warm_s}  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=40)
    ap.add_argument("--warmup", type=int, default=5)
    ap.add_argument("--batch", type=int, default=BATCH)
    ap.add_argument("--no-compile", action="store_true")
    ap.add_argument("--compiled-only", action="store_true", help="only the torch.compile rows")
    args = ap.parse_args()
    load = os.getloadavg()[0]
    print(f"torch {torch.__version__}, {os.cpu_count()} CPUs, load average {load:.1f}, "
          f"batch {args.batch}, median of {args.steps} steps")  # fmt: skip
    print("| threads | memory format | compiled | wall ms/step | CPU ms/step | steps/s (wall) | "
          "warm-up s |")  # fmt: skip
    print("|---|---|---|---|---|---|---|")
    variants = (
        [] if args.compiled_only else [(t, cl, False) for t in (1, 2) for cl in (False, True)]
    )
    if not args.no_compile:
        variants += [(t, cl, True) for t in (1, 2) for cl in (False, True)]
    for threads, channels_last, compiled in variants:
        name = f"| {threads} | {'channels_last' if channels_last else 'contiguous'} | " + (
            "yes" if compiled else "no") + " |"  # fmt: skip
        try:
            r = measure(threads, channels_last, compiled, args)
        except Exception as exc:  # torch.compile needs a C++ toolchain; say why it failed
            reason = str(exc).strip().splitlines()[0][:120] if str(exc).strip() else type(exc)
            print(f"{name} failed: {reason} | | | |")
            continue
        print(f"{name} {r['wall_ms']:.1f} | {r['cpu_ms']:.1f} | {1e3 / r['wall_ms']:.2f} | "
              f"{r['warmup_s']:.1f} |")  # fmt: skip


if __name__ == "__main__":
    main()
