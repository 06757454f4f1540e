"""Arithmetic whose result is the same bits on every x86-64 machine: sums in an order fixed
here, built only from operations IEEE 754 rounds exactly.

Why: an exploration run turns a difference in the last bit of one distance into another run.
numpy hands a float64 matrix or dot product (``@``, ``np.dot``, and so ``np.linalg.norm`` of
a vector) to OpenBLAS, which picks a kernel by CPU (``OPENBLAS_CORETYPE`` forces one) and
splits the work by thread count: each kernel sums in its own order, with or without fused
multiply-add, and the last bit differs (measured: a 200k-element dot product and a (10k, 20)
matrix-vector product under Prescott, Haswell and SkylakeX give three different results).
numpy's ``exp``, ``log``, ``arctan2``, ``tanh`` and ``power`` run SIMD versions chosen by CPU
that differ from the scalar ones in the last bit (``NPY_DISABLE_CPU_FEATURES`` shows it).

What does not vary: elementwise ``+ - * /``, ``sqrt``, comparisons, ``floor``, ``rint``,
``ldexp`` and ``frexp`` of float64 are exactly rounded (or exact) in every implementation,
SIMD or not, and two numpy ufunc calls are never fused into one multiply-add. Everything here
is built from those, one ufunc call per operation, in the order the docstrings give, so it is
a function of its inputs alone. ``tests/plumbing/test_fixed_order.py`` runs it under every
OpenBLAS kernel, thread count and numpy CPU feature set and compares the bits.

The C library's ``exp``, ``log``, ``sin``, ``cos`` and ``atan2`` are not used: glibc picks a
variant by CPU (with or without fused multiply-add), and numpy's float64 ``sin`` and ``cos``
call them; ``sin_cos`` here is fdlibm's algorithm in numpy operations. docs/determinism.md
says what is covered.
"""

from __future__ import annotations

import numpy as np

# fdlibm's split of ln 2 (e_exp.c): LN2_HI has its low 32 bits zero, so k * LN2_HI is exact
# for |k| < 2^20
LN2_HI = 6.93147180369123816490e-01
LN2_LO = 1.90821492927058770002e-10
INV_LN2 = 1.44269504088896338700e00
SQRT_HALF = 0.70710678118654752440
# exp's Taylor series to degree 13 on |r| <= ln(2) / 2: truncation below 4e-18 (relative)
_EXP_TERMS = 13
_EXP_COEFFS = [1.0]
for _n in range(1, _EXP_TERMS + 1):
    _EXP_COEFFS.append(_EXP_COEFFS[-1] / _n)
# log's series 2 s (1 + z/3 + z^2/5 + ...), z = s^2, |s| <= 0.1716: to z^9, truncation 1e-17
_LOG_TERMS = 10
# sq_distances: up to this many points a cumulative sum along the rows is the faster way
# (measured: 1 point 4.6 against 18 us column by column at 6-D; 200 points 22 against 14 us)
_FEW_POINTS = 16
# exp's argument range: below, exp underflows to 0; above, it overflows to infinity
_EXP_MIN, _EXP_MAX = -746.0, 710.0


def sq_distances(points: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Squared Euclidean distances of ``points`` (n, d) to ``q`` (d,): for each point,
    ``(p_0 - q_0)^2 + (p_1 - q_1)^2 + ...`` summed left to right. Shape (n,).

    Each partial sum is the previous one plus the next square, a chain of single additions no
    implementation can reorder (a reduction, ``np.sum``, may: numpy's is pairwise, in blocks of
    8): for a few points a cumulative sum along each row, for many a column added to a vector
    at a time (faster; the same additions in the same order)."""
    points = np.asarray(points, dtype=float)
    q = np.asarray(q, dtype=float).reshape(-1)
    n, d = points.shape
    if d != len(q):
        raise ValueError(f"points have {d} coordinates, the query {len(q)}")
    if d == 0:
        return np.zeros(n)
    diff = points - q
    diff *= diff
    if n <= _FEW_POINTS:
        return np.add.accumulate(diff, axis=1)[:, -1]
    out = diff[:, 0].copy()
    for j in range(1, d):
        out += diff[:, j]
    return out


def sq_norm(v: np.ndarray) -> float:
    """``v_0^2 + v_1^2 + ...`` of a vector (d,), summed left to right (as ``sq_distances``)."""
    v = np.asarray(v, dtype=float).reshape(-1)
    if not len(v):
        return 0.0
    return float(np.add.accumulate(v * v)[-1])


def norm(v: np.ndarray) -> float:
    """Euclidean norm of a vector (d,): ``sqrt(sq_norm(v))``."""
    return float(np.sqrt(sq_norm(v)))


def distance(a: np.ndarray, b: np.ndarray) -> float:
    """Euclidean distance between two vectors (d,): ``sqrt`` of ``sq_distances``."""
    a = np.asarray(a, dtype=float).reshape(1, -1)
    return float(np.sqrt(sq_distances(a, b)[0]))


def matmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a @ b`` summed over the shared axis k = 0, 1, ... left to right: ``a`` (..., m, K),
    ``b`` (..., K, n) broadcast as ``np.matmul``'s batch axes, or ``b`` (K,) for a
    matrix-vector product (then shape (..., m)). Cost: 2 K elementwise operations on the
    output's shape, so for the small K of a motor primitive (7) it is as fast as BLAS."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    k = a.shape[-1]
    if b.shape[0 if b.ndim == 1 else -2] != k:
        raise ValueError(f"matmul: shapes {a.shape} and {b.shape} do not match")
    if b.ndim == 1:
        out = a[..., 0] * b[0]
        for j in range(1, k):
            out = out + a[..., j] * b[j]
        return out
    out = a[..., :, 0:1] * b[..., 0:1, :]
    for j in range(1, k):
        out = out + a[..., :, j : j + 1] * b[..., j : j + 1, :]
    return out


def exp(x: np.ndarray) -> np.ndarray:
    """e^x elementwise, within 2 ulp of the exact value (``tests/plumbing``): x = k ln 2 + r
    (Cody and Waite's reduction with fdlibm's split of ln 2), e^r by its Taylor series to
    degree 13 in Horner's order, times 2^k. 0 below -746, inf above 710, NaN for NaN."""
    # in place on two buffers (large arrays: a temporary per step cost more than the step)
    x = np.asarray(x, dtype=float)
    r = np.clip(x.reshape(-1) if x.ndim == 0 else x, _EXP_MIN, _EXP_MAX)  # a new array, NaN kept
    nan = np.isnan(r)
    has_nan = bool(nan.any())
    if has_nan:
        r[nan] = 0.0
    k = r * INV_LN2
    np.rint(k, out=k)
    p = k * LN2_HI
    r -= p  # r = (x - k LN2_HI) - k LN2_LO
    np.multiply(k, LN2_LO, out=p)
    r -= p
    np.multiply(r, _EXP_COEFFS[-1], out=p)  # Horner: p = (c13 r + c12) r + c11 ...
    p += _EXP_COEFFS[-2]
    for c in reversed(_EXP_COEFFS[:-2]):
        p *= r
        p += c
    with np.errstate(over="ignore", under="ignore"):
        np.ldexp(p, k.astype(np.int32), out=p)  # int32: numpy's fast loop (int64: 15x slower)
    if has_nan:
        p[nan] = np.nan
    return p.reshape(x.shape)


def log(x: np.ndarray) -> np.ndarray:
    """Natural logarithm elementwise, within 2 ulp (``tests/plumbing``): x = m 2^e with m in
    [sqrt(1/2), sqrt(2)), f = m - 1, log m = 2 atanh(s) with s = f / (2 + f), by its series to
    s^19 in Horner's order, summed in fdlibm's order (e_log.c), plus e ln 2. -inf at 0, NaN
    below 0 and for NaN, inf at inf."""
    x = np.asarray(x, dtype=float)
    finite = np.isfinite(x) & (x > 0)
    m, e = np.frexp(np.where(finite, x, 1.0))
    low = m < SQRT_HALF
    m = np.where(low, m * 2.0, m)
    e = (e - low).astype(float)
    f = m - 1.0  # exact
    s = f / (2.0 + f)
    z = s * s
    r = np.full_like(z, 2.0 / (2 * _LOG_TERMS - 1))
    for i in range(_LOG_TERMS - 2, 0, -1):
        r = r * z + 2.0 / (2 * i + 1)
    r = r * z  # log(1 + f) = 2 s + s r
    hfsq = 0.5 * f * f
    # fdlibm's order (e_log.c): f - s (f - r) rewritten around f^2 / 2
    out = e * LN2_HI - ((hfsq - (s * (hfsq + r) + e * LN2_LO)) - f)
    out = np.where(finite, out, np.nan)
    out = np.where(x == 0, -np.inf, out)
    return np.where(np.isposinf(x), np.inf, out)


# fdlibm's split of pi / 2 (e_rem_pio2.c): PIO2_1 and PIO2_2 hold 33 bits each, so n * PIO2_1
# and n * PIO2_2 are exact for |n| < 2^20; PIO2_2T is what is left of pi / 2
INV_PIO2 = 6.36619772367581382433e-01
PIO2_1 = 1.57079632673412561417e00
PIO2_2 = 6.07710050630396597660e-11
PIO2_2T = 2.02226624879595063154e-21
# fdlibm's minimax kernels on [-pi/4, pi/4] (k_sin.c, k_cos.c)
_SIN = (
    -1.66666666666666324348e-01, 8.33333333332248946124e-03, -1.98412698298579493134e-04,
    2.75573137070700676789e-06, -2.50507602534068634195e-08, 1.58969099521155010221e-10,
)  # fmt: skip
_COS = (
    4.16666666666666019037e-02, -1.38888888888741095749e-03, 2.48015872894767294178e-05,
    -2.75573143513906633035e-07, 2.08757232129817482790e-09, -1.13596475577881948265e-11,
)  # fmt: skip
_TRIG_MAX = 1e6  # |x| above: the reduction's n leaves the exact range (not needed here)


def sin_cos(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """sin x and cos x elementwise, within 2 ulp for |x| <= 1e6 (``tests/plumbing``): fdlibm's
    algorithm (Cody and Waite's reduction by pi / 2 in three parts, then its minimax kernels in
    their order, k_sin.c and k_cos.c), without the C library, whose variant depends on the
    CPU. Raises ``ValueError`` beyond |x| 1e6 or for NaN and infinities."""
    x = np.asarray(x, dtype=float)
    if not np.all(np.abs(x) <= _TRIG_MAX):
        raise ValueError(f"sin_cos takes |x| <= {_TRIG_MAX:g}, finite")
    n = np.rint(x * INV_PIO2)
    y = (x - n * PIO2_1) - n * PIO2_2
    y = y - n * PIO2_2T
    z = y * y
    r = _SIN[1] + z * (_SIN[2] + z * (_SIN[3] + z * (_SIN[4] + z * _SIN[5])))
    s = y + (z * y) * (_SIN[0] + z * r)
    rc = z * (_COS[0] + z * (_COS[1] + z * (_COS[2] + z * (_COS[3] + z * (_COS[4] + z * _COS[5])))))
    hz = 0.5 * z
    w = 1.0 - hz
    c = w + (((1.0 - w) - hz) + z * rc)
    q = n.astype(np.int64) & 3
    sin = np.where(q == 0, s, np.where(q == 1, c, np.where(q == 2, -s, -c)))
    cos = np.where(q == 0, c, np.where(q == 1, -s, np.where(q == 2, -c, s)))
    return sin, cos
