"""The same seed gives the same run on every x86-64 machine: short runs of every strategy without
a neural network (testkit/determinism.py) in subprocesses under each OpenBLAS kernel, one and
two BLAS threads, and numpy with its SIMD code paths disabled, one fingerprint each, equal to
the golden one committed here (docs/determinism.md).

The golden fingerprints change only when a change alters what runs explore. Such a change is
deliberate: run ``python -m testkit.determinism`` (default settings), paste its output into
``GOLDEN``, and say in the commit why the trajectories changed; the first runs' figures
(docs/determinism.md, "The first runs") are checked the same way.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from testkit.determinism import SETTINGS

ROOT = Path(__file__).resolve().parents[2]

GOLDEN = {
    "twin-rpe": "c87bf469dab1ba4897844aa4442939f421180ce37710539fb61dde8c8b8ab6c4",
    "twin-rge-efr": "af69a4e54b5f37e3a184f7c28f12bb0222854bb8735028efb171832ae02689c5",
    "twin-mge-efr": "ab27a89c15124a2c32845267daeb94271d452f34fa34a74f2189f9941ed42c79",
    "twin-rge-efr-frontier": "16834688d8e49af2221e0ebe3e1878dbc4d18b95f3221db9517e467dc03d9a79",
    "arm2balls-rge-corl2018": "5e2ee07f6deb5db6b9a015c882989a8da5b65598b598c4215afff8e0a460edf9",
    "arm2balls-mge-corl2018": "3359c25cd8fc0279ac9f9d5183de1a383748c9990b5dff24d4fb95fbab7b4be5",
    "armballs-rge-efr-density": "024ce932ed4c752d6c36ea2bf109cb12384dcce2d3a6a191b9aab56becf2f942",
}  # fmt: skip


def run_python(args: list[str], env: dict[str, str], timeout: float) -> str:
    full = {**os.environ, "PYTHONPATH": str(ROOT), "MUJOCO_GL": "egl", **env}
    done = subprocess.run(
        [sys.executable, *args], cwd=ROOT, env=full, capture_output=True, text=True,
        timeout=timeout,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr[-2000:]
    return done.stdout


# ``ERGO_TEST_NUDGE_ULP=1`` (tests/nudge_twin.py) moves every twin run off its golden
# fingerprint on purpose: then the settings are compared with the default setting's runs
NUDGED = os.environ.get("ERGO_TEST_NUDGE_ULP") == "1"


@pytest.fixture(scope="module")
def expected() -> dict[str, str]:
    """The golden fingerprints, or the default setting's under the nudge."""
    if not NUDGED:
        return GOLDEN
    return json.loads(run_python(["-m", "testkit.determinism"], {}, 300))


def test_short_runs_match_their_golden_fingerprints():
    from testkit.determinism import SHORT_RUNS

    assert set(SHORT_RUNS) == set(GOLDEN)
    if NUDGED:
        pytest.skip("the twin is nudged: its runs are not the golden ones")
    out = json.loads(run_python(["-m", "testkit.determinism"], {}, 300))
    assert out == GOLDEN


@pytest.mark.parametrize("setting", list(SETTINGS))
def test_one_fingerprint_per_strategy_whatever_the_kernel_threads_and_simd(setting, expected):
    out = json.loads(run_python(["-m", "testkit.determinism"], SETTINGS[setting], 300))
    assert out == expected


# glibc's libm without its FMA variant, as on a CPU without FMA (docs/determinism.md)
NO_FMA_LIBM = {"GLIBC_TUNABLES": "glibc.cpu.hwcaps=-AVX2,-FMA,-AVX512F"}
LIBM_PROBE = (
    "import hashlib, math, struct; "
    "print(hashlib.sha256(b''.join(struct.pack('<d', math.sin(0.001 * k)) "
    "for k in range(100000))).hexdigest())"
)


def test_armballs_runs_do_not_depend_on_the_c_library_variant():
    # ArmBalls is numpy and our own arithmetic only: its runs are the same with glibc's
    # non-FMA libm; the twin's are not (MuJoCo's physics calls the C library)
    if run_python(["-c", LIBM_PROBE], NO_FMA_LIBM, 60) == run_python(["-c", LIBM_PROBE], {}, 60):
        pytest.skip("this C library ignores GLIBC_TUNABLES' hwcaps: nothing to compare")
    names = [name for name in GOLDEN if name.startswith("arm")]
    out = json.loads(run_python(["-m", "testkit.determinism", *names], NO_FMA_LIBM, 300))
    assert out == {name: GOLDEN[name] for name in names}


# The first runs: the README's first task and ``make run``, their figures in one place
FIRST_RUNS_PAGE = ROOT / "docs" / "determinism.md"
FIRST_RUNS = {  # the page's row label -> the command's strategy
    "the README's first task": "rge-efr",
    "`make run`": "rpe",
}


def first_runs_table() -> dict[str, tuple[int, str]]:
    """docs/determinism.md's first runs: strategy -> (ball cells, fingerprint)."""
    text = FIRST_RUNS_PAGE.read_text()
    out = {}
    for label, strategy in FIRST_RUNS.items():
        row = re.search(
            rf"^\| {re.escape(label)} \| `[^`]*--strategy {strategy} [^`]*` \| (\d+) \| "
            r"`([0-9a-f]{64})` \|$",
            text,
            re.M,
        )
        assert row, f"docs/determinism.md has no first-runs row for {label}"
        out[strategy] = int(row.group(1)), row.group(2)
    return out


def test_the_first_runs_give_the_figures_the_docs_quote(tmp_path):
    if NUDGED:
        pytest.skip("the twin is nudged: the docs quote the unnudged twin's figures")
    table = first_runs_table()
    script = (
        "import sys\n"
        "from explore.cli import main\n"
        "for s in ('rge-efr', 'rpe'):\n"
        "    main(['explore', '--rig', 'sim', '--strategy', s, '--episodes', '300', '--seed',"
        " '0', '--out', sys.argv[1] + '/' + s, '--no-progress'])\n"
        "main(['runs', 'fingerprint', sys.argv[1] + '/rge-efr', sys.argv[1] + '/rpe'])\n"
    )
    # under a kernel and SIMD setting other than this machine's: the figures are everyone's
    out = run_python(["-c", script, str(tmp_path)], SETTINGS["prescott-1-thread-no-simd"], 600)
    for strategy, (cells, digest) in table.items():
        assert f"{digest}  {tmp_path}/{strategy}: 300 episodes, {cells} ball cells" in out
    rge, rpe = table["rge-efr"][0], table["rpe"][0]
    # every page that quotes them quotes the same
    readme = (ROOT / "README.md").read_text()
    assert f"ends at {rpe} ball cells and the rge-efr run above at {rge}" in readme
    warm = (ROOT / "docs" / "warm_start.md").read_text()
    assert f"figure at 300 episodes from scratch is {rge} cells" in warm
    assert f"twin reaches in one process ({rge})" in warm
    real = (ROOT / "docs" / "real_arm.md").read_text()
    assert f"| the nominal twin in one process (`--rig sim`), the same seed | {rge} |" in real
