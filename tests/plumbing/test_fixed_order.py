"""Fixed-order arithmetic: its sums are in the order it says, its exp, log, sin and cos within
2 ulp, and
its results (and the nearest-neighbour index's large scans, which BLAS only proposes candidates
for) the same bits under every OpenBLAS kernel, thread count and numpy CPU feature set."""

from __future__ import annotations

import hashlib
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from plumbing import fixed_order

ROOT = Path(__file__).resolve().parents[2]


def test_sums_run_left_to_right():
    # 1 + 1e-16 + ... is lost left to right; another order would keep some of it
    p = np.array([[1.0, 1e-8, 1e-8, 1e-8]])
    expected = ((1.0 + 1e-16) + 1e-16) + 1e-16
    assert fixed_order.sq_distances(p, np.zeros(4))[0] == expected
    a = np.array([[1.0, 1e-16, 1e-16, 1e-16]])
    assert fixed_order.matmul(a, np.ones(4))[0] == expected
    assert fixed_order.matmul(a, np.ones((4, 1)))[0, 0] == expected
    assert fixed_order.norm([3.0, 4.0]) == 5.0 and fixed_order.distance([1, 1], [4, 5]) == 5.0


def test_matmul_broadcasts_like_numpy():
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(40, 7)), rng.normal(size=(5, 7, 6))
    np.testing.assert_allclose(fixed_order.matmul(a, b), a @ b, rtol=1e-13, atol=1e-13)
    with pytest.raises(ValueError, match="do not match"):
        fixed_order.matmul(a, np.ones(6))


def _ulps(got: np.ndarray, ref: np.ndarray) -> np.ndarray:
    return np.abs(got - ref) / np.spacing(np.abs(ref))


def test_exp_and_log_are_within_two_ulp_of_the_c_library():
    rng = np.random.default_rng(1)
    x = np.concatenate([rng.uniform(-745, 709, 20000), rng.uniform(-3, 3, 20000)])
    ref = np.array([math.exp(v) for v in x])
    assert _ulps(fixed_order.exp(x), ref)[ref > 0].max() <= 2
    special = fixed_order.exp(np.array([-np.inf, np.inf, np.nan, 0.0, -800.0, 800.0]))
    np.testing.assert_array_equal(special, [0.0, np.inf, np.nan, 1.0, 0.0, np.inf])
    y = np.concatenate([np.exp(rng.uniform(-700, 700, 20000)), rng.uniform(0.5, 2, 20000)])
    ref = np.array([math.log(v) for v in y])
    assert _ulps(fixed_order.log(y), ref)[ref != 0].max() <= 2
    special = fixed_order.log(np.array([0.0, -1.0, np.inf, np.nan, 1.0]))
    np.testing.assert_array_equal(special, [-np.inf, np.nan, np.inf, np.nan, 0.0])


def test_sin_and_cos_are_within_two_ulp_of_the_c_library():
    rng = np.random.default_rng(3)
    x = np.concatenate([rng.uniform(-25, 25, 20000), rng.uniform(-1e6, 1e6, 5000)])
    x = np.concatenate([x, np.arange(-20, 21) * np.pi / 2, rng.uniform(-1e-3, 1e-3, 1000)])
    sin, cos = fixed_order.sin_cos(x)
    for got, f in ((sin, math.sin), (cos, math.cos)):
        ref = np.array([f(v) for v in x])
        assert _ulps(got, ref).max() <= 2
    assert fixed_order.sin_cos(0.0) == (0.0, 1.0)
    with pytest.raises(ValueError, match="1e"):
        fixed_order.sin_cos(np.array([0.0, np.nan]))


BITS = """
import hashlib, numpy as np
from plumbing import fixed_order as f
from explore.learner.meta_policy import NearestNeighbourIndex
rng = np.random.default_rng(2)
h = hashlib.sha256()
p, q = rng.normal(size=(5000, 20)), rng.normal(size=20)
for v in (f.sq_distances(p, q), f.matmul(p[:, :7], rng.normal(size=(7, 6))),
          f.exp(rng.uniform(-50, 50, 5000)), f.log(rng.uniform(0, 50, 5000)),
          *f.sin_cos(rng.uniform(-30, 30, 5000)),
          np.array([f.norm(p[0]), f.distance(p[1], p[2])])):
    h.update(np.ascontiguousarray(v).tobytes())
# 20-D: every query scans all points through BLAS's matrix-vector product; 6-D with a long
# tail: the tree plus a scan of up to 1024 points the same way
for dim, tail in ((20, 1024), (6, 1024)):
    index = NearestNeighbourIndex(dim, tail)
    pts = np.round(rng.normal(size=(3000, dim)), 1)  # a coarse grid: many near ties
    for x in pts:
        index.add(x)
    for x in np.round(rng.normal(size=(300, dim)), 1) + 0.05:
        h.update(np.array(index.nearest(x)).tobytes())
print(h.hexdigest())
"""


def test_the_same_bits_under_every_blas_kernel_thread_count_and_simd_setting():
    from testkit.determinism import SETTINGS

    out = set()
    for env in [{}, *SETTINGS.values()]:
        full = {**os.environ, "PYTHONPATH": str(ROOT), **env}
        done = subprocess.run(
            [sys.executable, "-c", BITS], cwd=ROOT, env=full, capture_output=True, text=True,
            timeout=120,
        )  # fmt: skip
        assert done.returncode == 0, done.stderr[-2000:]
        out.add(done.stdout.strip())
    assert len(out) == 1
    assert len(hashlib.sha256().hexdigest()) == len(out.pop())
