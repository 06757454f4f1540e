"""``ergo explore --warm-start TWIN_RUN``: a run on the twin given a stand-in's hidden servos
(the "arm", in process), warmed by a run on the nominal twin. The prior never appears as the
arm's data (history, metrics, export); the run is a function of its seed and its prior (and a
resume replays it); a changed, missing or incompatible prior is refused in one line; a SIGKILL
or a Ctrl-C leaves the run resumable with its prior."""

from __future__ import annotations

import csv
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from calibration import store as cal_store
from explore.cli import main
from explore.runs.layout import HISTORY_FILE, METRICS_FILE, PRIOR_KEY, REALITY_GAP_FILE
from explore.runs.store import read_history
from sim.standin.hidden import draw_hidden

PRIOR_EPISODES, ARM_EPISODES, BOOT = 40, 24, 10
STANDIN = 301  # a development stand-in (docs: 300-399); its hidden servos, bench-style
ARM_ID = "s301-hidden"
QUIET = ["--no-progress", "--rerun", "off"]
FAST = ["--rig-option", "render_size=[64,64]", *QUIET]


def _explore(out: Path, *extra: str, episodes: int = ARM_EPISODES) -> int:
    return main(
        ["explore", "--strategy", "rge-efr", "--strategy-option", f"bootstrap={BOOT}",
         "--episodes", str(episodes), "--out", str(out), *FAST, *extra]
    )  # fmt: skip


@pytest.fixture(scope="module")
def cal_dir(tmp_path_factory) -> Path:
    """A calibration folder with stand-in 301's hidden servos as rig s301-hidden's twin."""
    root = tmp_path_factory.mktemp("cal")
    payload = {
        "servos": draw_hidden(STANDIN).servos.to_dict(),
        "recording": {"path": "hidden.npz", "sha256": "0" * 64},
        "held_out_rms_rad": {"nominal": 0.0, "fitted": 0.0},
    }
    cal_store.save("dynamics", ARM_ID, payload, root)
    return root


@pytest.fixture(autouse=True)
def _calibrations(cal_dir, monkeypatch):
    monkeypatch.setenv(cal_store.ENV_DIR, str(cal_dir))


@pytest.fixture(scope="module")
def prior(tmp_path_factory, cal_dir) -> Path:
    out = tmp_path_factory.mktemp("twin") / "prior"
    os.environ[cal_store.ENV_DIR] = str(cal_dir)
    assert _explore(out, "--rig", "sim", "--seed", "1", episodes=PRIOR_EPISODES) == 0
    return out


def _arm(out: Path, prior: Path, *extra: str, episodes: int = ARM_EPISODES) -> int:
    return _explore(
        out, "--rig", "sim", "--rig-id", ARM_ID, "--seed", "2", "--warm-start", str(prior),
        *extra, episodes=episodes,
    )  # fmt: skip


@pytest.fixture(scope="module")
def warmed(tmp_path_factory, prior, cal_dir) -> Path:
    out = tmp_path_factory.mktemp("arm") / "warm"
    os.environ[cal_store.ENV_DIR] = str(cal_dir)
    assert _arm(out, prior) == 0
    return out


def _gap(run: Path) -> list[dict]:
    with (run / REALITY_GAP_FILE).open() as f:
        return list(csv.DictReader(f))


def test_the_prior_seeds_the_arm_and_its_answers_are_in_the_gap_file(warmed, prior):
    arm = read_history(warmed).records
    twin = read_history(prior).records
    rows = _gap(warmed)
    # the prior (40 >= bootstrap 10) stands for the bootstrap: goals from the first episode
    assert arm[0].kind == "explore"
    assert len(rows) >= 3
    for row in rows:
        k, j = int(row["episode"]), int(row["prior_episode"])
        assert arm[k].kind == row["kind"]
        np.testing.assert_allclose(
            [float(row["prior_x"]), float(row["prior_y"])], twin[j].ball, rtol=1e-5
        )
        np.testing.assert_allclose(
            [float(row["arm_x"]), float(row["arm_y"])], arm[k].ball, rtol=1e-5
        )
        if row["kind"] == "exploit":  # no noise: the twin's very parameters
            np.testing.assert_array_equal(arm[k].theta, twin[j].theta)
    # each prior episode answers once
    assert len({r["prior_episode"] for r in rows}) == len(rows)
    meta = json.loads((warmed / "run.json").read_text())
    assert meta[PRIOR_KEY]["path"] == str(prior.resolve())
    assert meta[PRIOR_KEY]["episodes"] == PRIOR_EPISODES
    assert meta["config"]["warm_start"] == str(prior.resolve())


def test_the_prior_never_appears_as_the_arms_data(warmed, prior, tmp_path):
    arm = read_history(warmed).records
    twin = read_history(prior).records
    assert [r.episode for r in arm] == list(range(ARM_EPISODES))
    twin_thetas = {r.theta.tobytes() for r in twin}
    # an explore episode plays a prior entry's parameters plus noise: never a twin record's
    explored = [r for r in arm if r.kind == "explore"]
    assert explored and all(r.theta.tobytes() not in twin_thetas for r in explored)
    lines = (warmed / METRICS_FILE).read_text().strip().splitlines()
    assert len(lines) == 1 + ARM_EPISODES  # header + the arm's own episodes only
    pytest.importorskip("pyarrow")
    pytest.importorskip("av")
    out = tmp_path / "ds"
    assert main(["export", "lerobot", str(warmed), "--out", str(out)]) == 0
    info = json.loads((out / "meta/info.json").read_text())
    assert info["total_episodes"] == ARM_EPISODES


def test_the_run_is_a_function_of_its_seed_and_prior_and_a_resume_replays_it(
    warmed, prior, tmp_path
):
    out = tmp_path / "again"
    assert _arm(out, prior, episodes=10) == 0
    assert _arm(out, prior, "--resume-or-new") == 0  # replays the 10 with the prior, goes on
    a, b = read_history(warmed).records, read_history(out).records
    assert len(a) == len(b) == ARM_EPISODES
    assert all(x.equals(y) for x, y in zip(a, b, strict=True))
    assert _gap(out) == _gap(warmed)


def test_scratch_differs_from_warm(warmed, tmp_path):
    out = tmp_path / "scratch"
    assert _explore(out, "--rig", "sim", "--rig-id", ARM_ID, "--seed", "2") == 0
    scratch = read_history(out).records
    assert scratch[0].kind == "random"  # its own bootstrap
    assert not (out / REALITY_GAP_FILE).exists()
    assert "warm_start" not in json.loads((out / "run.json").read_text())["config"]


def _copy(run: Path, to: Path) -> Path:
    shutil.copytree(run, to, ignore=shutil.ignore_patterns("writer.lock"))
    return to


def test_a_changed_or_missing_prior_is_refused_naming_the_override(warmed, prior, tmp_path, capsys):
    twin = _copy(prior, tmp_path / "twin")
    arm = tmp_path / "arm"
    assert _arm(arm, twin, episodes=8) == 0
    assert main(["explore", "--resume", str(arm), "--episodes", "10", *FAST]) == 0
    data = (twin / HISTORY_FILE).read_bytes()
    (twin / HISTORY_FILE).write_bytes(data[: len(data) // 2])  # changed
    capsys.readouterr()
    assert main(["explore", "--resume", str(arm), "--episodes", "12", *FAST]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("ergo: error:")
    assert f"its prior {twin}" in err[0] and "changed" in err[0]
    assert "--allow-changed-inputs" in err[0]
    shutil.rmtree(twin)  # missing
    assert main(["explore", "--resume", str(arm), "--episodes", "12", *FAST]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "is missing" in err[0] and "--allow-changed-inputs" in err[0]
    assert len(read_history(arm).records) == 10  # nothing run
    flags = ["--allow-changed-inputs"]
    assert main(["explore", "--resume", str(arm), "--episodes", "12", *FAST, *flags]) == 0
    meta = json.loads((arm / "run.json").read_text())
    assert PRIOR_KEY not in meta and meta["prior_before"][0]["until_episode"] == 10


def test_a_prior_missing_at_a_resume_stays_missing_when_it_comes_back(prior, tmp_path, capsys):
    # a 10-episode warmed run resumed to 16 without its prior, then to 18 with it back: the
    # episodes since 10 were chosen without a prior, so no resume attaches it again (once, it
    # was re-attached silently and reality_gap.csv gained rows 15 and 16)
    twin = _copy(prior, tmp_path / "twin")
    arm = tmp_path / "arm"
    assert _arm(arm, twin, episodes=10) == 0
    rows = _gap(arm)
    assert rows  # the prior answered some of the first 10
    twin.rename(tmp_path / "away")
    flags = ["--allow-changed-inputs"]
    assert main(["explore", "--resume", str(arm), "--episodes", "16", *FAST, *flags]) == 0
    meta = json.loads((arm / "run.json").read_text())
    assert meta["prior_detached"] == {"episode": 10, "path": str(twin)}
    (tmp_path / "away").rename(twin)
    capsys.readouterr()
    assert main(["explore", "--resume", str(arm), "--episodes", "18", *FAST]) == 0
    err = capsys.readouterr().err
    assert f"its prior {twin} is back, but the run went on without it from episode 10" in err
    assert _gap(arm) == rows
    assert len(read_history(arm).records) == 18


def test_an_incompatible_prior_is_refused_in_one_line(prior, tmp_path, capsys):
    cases = [
        (["--strategy", "mge-efr"], "explored with rge-efr, this run with mge-efr"),
        (["--strategy-option", 'form="polar"'], "another goal space"),
        (["--strategy", "rpe"], "explored with rge-efr, this run with rpe"),
        (["--rig", "armballs"], "another scene"),
    ]
    for i, (flags, words) in enumerate(cases):
        out = tmp_path / f"bad{i}"
        capsys.readouterr()
        args = ["explore", "--rig", "sim", "--strategy", "rge-efr", "--episodes", "3",
                "--out", str(out), "--warm-start", str(prior), *QUIET, *flags]  # fmt: skip
        assert main(args) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("ergo: error:"), (flags, err)
        assert words in err[0], (flags, err)
        assert not out.exists()  # nothing made
    args = ["explore", "--episodes", "3", "--out", str(tmp_path / "x"), "--strategy", "rge-efr",
            "--warm-start", str(tmp_path / "nothing"), *FAST]  # fmt: skip
    assert main(args) == 2
    assert "no run there" in capsys.readouterr().err


def _child(out: Path, prior: Path, episodes: int) -> subprocess.Popen:
    cmd = [sys.executable, "-m", "explore.cli", "explore", "--rig", "sim", "--rig-id", ARM_ID,
           "--strategy", "rge-efr", "--strategy-option", f"bootstrap={BOOT}", "--seed", "2",
           "--episodes", str(episodes), "--out", str(out), "--resume-or-new",
           "--warm-start", str(prior), *FAST]  # fmt: skip
    return subprocess.Popen(
        cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True,
        env={**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")},
    )  # fmt: skip


def _wait_for(out: Path, episodes: int, proc: subprocess.Popen, limit_s: float = 120) -> None:
    end = time.monotonic() + limit_s
    while time.monotonic() < end and proc.poll() is None:
        if (out / HISTORY_FILE).exists():
            try:
                if len(read_history(out).records) >= episodes:
                    return
            except Exception:
                pass
        time.sleep(0.05)
    pytest.fail(f"the run did not reach {episodes} episodes (exit {proc.poll()})")


@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGINT])
def test_a_kill_or_ctrl_c_keeps_the_run_resumable_with_its_prior(warmed, prior, tmp_path, sig):
    out = tmp_path / "killed"
    proc = _child(out, prior, ARM_EPISODES)
    _wait_for(out, 6, proc)
    os.killpg(proc.pid, sig)
    proc.communicate(timeout=60)
    assert proc.returncode == (-9 if sig == signal.SIGKILL else 130)
    done = len(read_history(out).records)
    assert done < ARM_EPISODES
    resumed = _child(out, prior, ARM_EPISODES)
    _, err = resumed.communicate(timeout=300)
    assert resumed.returncode == 0, err.decode()[-2000:]
    a, b = read_history(warmed).records, read_history(out).records
    assert all(x.equals(y) for x, y in zip(a, b, strict=True)) and len(b) == ARM_EPISODES
    assert _gap(out) == _gap(warmed)


def test_the_report_shows_the_reality_gap(warmed, tmp_path, capsys):
    out = tmp_path / "report"
    capsys.readouterr()
    assert main(["report", str(warmed), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    line = next(x for x in printed.splitlines() if x.startswith("reality gap:"))
    n = len(_gap(warmed))
    assert f"{n} episodes played the prior's parameters" in line and "median distance" in line
    assert (out / "reality_gap.png").stat().st_size > 10_000
    assert "reality gap (the prior's outcome against the arm's)" in (out / "summary.md").read_text()


def test_a_campaign_warms_each_trial(prior, tmp_path):
    out = tmp_path / "campaign"
    args = ["experiment", "--strategies", "rge-efr", "--seeds", "2", "--episodes", "6",
            "--out", str(out), "--warm-start", str(prior), "--rig", "sim", "--rig-id", ARM_ID,
            "--option", f"bootstrap={BOOT}", "--rig-option", "render_size=[64,64]",
            "--no-progress", "--no-report"]  # fmt: skip
    assert main(args) == 0
    for seed in (0, 1):
        run = out / "rge-efr" / f"seed-{seed}"
        meta = json.loads((run / "run.json").read_text())
        assert meta["config"]["warm_start"] == str(prior.resolve())
        assert meta[PRIOR_KEY]["episodes"] == PRIOR_EPISODES
        assert read_history(run).records[0].kind == "explore"  # no bootstrap: the prior's
