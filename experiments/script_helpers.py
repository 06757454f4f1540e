"""What the scripts of experiments/ (and two of bench/) share: the R^2 of a linear probe, a
figure written to a file, a server subprocess stopped, the warm-start campaigns' flag
``--prior-context``. Not a script: imported by the scripts
beside it (a script's own folder is first on ``sys.path``); bench/bench_vae.py and
bench/bench_canopen.py put this folder on ``sys.path`` to import it.
"""

from __future__ import annotations

import argparse
import subprocess
from pathlib import Path
from typing import Any

import numpy as np

FIGURE_DPI = 110  # the resolution the docs' experiment figures were written at (docs/img)


def r2(pred: np.ndarray, truth: np.ndarray, *, pooled: bool) -> float:
    """R^2 of predictions ``pred`` of ``truth`` (n, k), both in the same units.

    ``pooled``: one R^2 over all k coordinates (the squared errors summed over every coordinate,
    over the squares about each column's mean, summed likewise); otherwise the mean of the k
    columns' own R^2.
    """
    err = ((pred - truth) ** 2).sum(axis=0)
    spread = ((truth - truth.mean(axis=0)) ** 2).sum(axis=0)
    if pooled:
        return float(1.0 - err.sum() / spread.sum())
    return float(np.mean(1.0 - err / spread))


def linear_r2(
    x_fit: np.ndarray,
    y_fit: np.ndarray,
    x_test: np.ndarray | None = None,
    y_test: np.ndarray | None = None,
    *,
    pooled: bool,
) -> float:
    """R^2 (``r2``) of the least-squares affine map x (n, d) -> y (n, k) fitted on
    (``x_fit``, ``y_fit``), scored on (``x_test``, ``y_test``), or on the fit's own rows when
    no test rows are given."""
    w, *_ = np.linalg.lstsq(np.hstack([x_fit, np.ones((len(x_fit), 1))]), y_fit, rcond=None)
    if x_test is None or y_test is None:
        x_test, y_test = x_fit, y_fit
    return r2(np.hstack([x_test, np.ones((len(x_test), 1))]) @ w, y_test, pooled=pooled)


def save_figure(fig: Any, path: Path) -> None:
    """Write a matplotlib figure to ``path`` (PNG at ``FIGURE_DPI``), close it, and say so."""
    import matplotlib.pyplot as plt

    fig.savefig(path, dpi=FIGURE_DPI)
    plt.close(fig)
    print(f"wrote {path}")


def stop_process(proc: subprocess.Popen, timeout_s: float) -> None:
    """SIGTERM ``proc``, wait up to ``timeout_s`` s for it to exit, then SIGKILL it."""
    proc.terminate()
    try:
        proc.wait(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


def add_prior_context(parser: argparse.ArgumentParser) -> None:
    """``--prior-context F``: the warmed runs' strategy option ``prior_context`` (rule 5 of
    explore/learner/prior.py); absent, the option's default."""
    parser.add_argument(
        "--prior-context", type=float, default=None,
        help="the warmed runs' option prior_context (default: its default)",
    )  # fmt: skip


def prior_option(args: argparse.Namespace) -> list[str]:
    """The ``ergo explore`` words for ``args.prior_context`` (``add_prior_context``), if given."""
    if args.prior_context is None:
        return []
    return ["--strategy-option", f"prior_context={args.prior_context}"]
