"""Campaigns on Ray: the same per-seed results as the local backend, a killed worker leaves a
resumable run, physical rigs as custom resources (one trial at a time per rig, calibration found
by rig id on the worker, a missing rig refused up front), and a one-line install hint.

One Ray instance for the module, on this machine only: 127.0.0.1, 2 CPUs, no dashboard, usage
statistics off, the smallest object store, and the resource of a pretend rig ``ergo1``.
"""

from __future__ import annotations

import csv
import json
import os
import signal
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

# read when Ray is imported (explore/campaigns/ray_backend.py import_ray says why)
os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
os.environ.setdefault("RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER", "0")

import pytest
import ray

from explore.campaigns.backends import BackendSettings
from explore.campaigns.plan import campaign_id, run_campaign
from explore.campaigns.ray_backend import LOCAL_OBJECT_STORE_BYTES, check_rig_resources, run_ray
from explore.campaigns.trial import CampaignError, Trial, run_trial, trial_resources
from explore.cli import main
from explore.runs.layout import HISTORY_FILE, METRICS_FILE, TRIAL_FILE

EPISODES = 20
STRATEGIES = ["rpe", "rge-efr"]
SEEDS = [0, 1]
OPTIONS = {"bootstrap": 10}


@pytest.fixture(scope="module")
def calibration_dir(tmp_path_factory) -> Path:
    """ERGO_CALIBRATION_DIR of the Ray workers (set before they start): empty."""
    return tmp_path_factory.mktemp("calibration")


@pytest.fixture(scope="module")
def cluster(calibration_dir):
    old = os.environ.get("ERGO_CALIBRATION_DIR")
    os.environ["ERGO_CALIBRATION_DIR"] = str(calibration_dir)  # inherited by the workers
    ray.init(
        address="local", num_cpus=2, resources={"rig:ergo1": 1}, include_dashboard=False,
        object_store_memory=LOCAL_OBJECT_STORE_BYTES,
    )  # fmt: skip
    yield ray
    ray.shutdown()
    if old is None:
        os.environ.pop("ERGO_CALIBRATION_DIR", None)
    else:
        os.environ["ERGO_CALIBRATION_DIR"] = old


@pytest.fixture(scope="module")
def local_reference(tmp_path_factory) -> Path:
    """The small campaign on the local backend (in this process)."""
    out = tmp_path_factory.mktemp("local") / "c"
    run_campaign(out, STRATEGIES, SEEDS, EPISODES, jobs=1, options=OPTIONS)
    return out


def _metrics(run_dir: Path) -> list[dict[str, str]]:
    with open(run_dir / METRICS_FILE, newline="") as f:
        return list(csv.DictReader(f))


def _args(out: Path, *extra: str) -> list[str]:
    return ["experiment", "--strategies", ",".join(STRATEGIES), "--seeds", "0,1",
            "--episodes", str(EPISODES), "--out", str(out), "--option", "bootstrap=10",
            "--no-progress", "--backend", "ray", *extra]  # fmt: skip


def test_local_ray_instance_listens_on_loopback_only(cluster):
    assert cluster.get_runtime_context().gcs_address.startswith("127.0.0.1:")
    assert all(n["NodeManagerAddress"] == "127.0.0.1" for n in cluster.nodes())


def test_ray_campaign_gives_the_local_backends_per_seed_results(cluster, local_reference, tmp_path):
    out = tmp_path / "ray"
    assert main(_args(out)) == 0
    with open(out / "summary.csv") as f, open(local_reference / "summary.csv") as g:
        assert f.read() == g.read()
    for s in STRATEGIES:
        for seed in SEEDS:
            run = out / s / f"seed-{seed}"
            # every episode's cells, not just the last: the same runs
            assert _metrics(run) == _metrics(local_reference / s / f"seed-{seed}")
    trial = (out / "rpe" / "seed-0" / TRIAL_FILE).read_text()
    assert f'"pid": {os.getpid()},' not in trial  # it ran in a Ray worker, not here
    stamp = (out / "rpe" / "seed-0" / HISTORY_FILE).stat().st_mtime_ns
    assert main(_args(out)) == 0  # finished trials are not re-run
    assert (out / "rpe" / "seed-0" / HISTORY_FILE).stat().st_mtime_ns == stamp


def _wait_for_rows(run_dir: Path, n: int, timeout_s: float = 60.0) -> None:
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        path = run_dir / METRICS_FILE
        if path.exists() and len(path.read_text().splitlines()) > n:
            return
        time.sleep(0.02)
    raise AssertionError(f"{run_dir}: fewer than {n} episodes after {timeout_s} s")


def _kill_trial_worker(run_dir: Path, after_rows: int) -> None:
    """SIGKILL the process running the trial once the run holds ``after_rows`` episodes."""
    _wait_for_rows(run_dir, after_rows)
    pid = json.loads((run_dir / TRIAL_FILE).read_text())["pid"]
    assert pid != os.getpid()
    os.kill(pid, signal.SIGKILL)


def test_a_worker_killed_mid_trial_leaves_a_run_that_resumes(cluster, local_reference, tmp_path):
    out = tmp_path / "c"
    long = 3 * EPISODES  # long enough to be killed before it ends
    trial = Trial.of(str(out / "rpe" / "seed-0"), "rpe", 0, long, campaign_id=campaign_id(out))
    run_dir = Path(trial.run_dir)
    with ThreadPoolExecutor(1) as pool:
        # no retry: the campaign fails in one line and leaves the run for a rerun
        driver = pool.submit(run_ray, [trial], BackendSettings(retries=0))
        _kill_trial_worker(run_dir, 2)
        with pytest.raises(CampaignError, match=r"1 trial\(s\) failed \(rpe seed 0: .*rerun"):
            driver.result(timeout=60)
        done = len(_metrics(run_dir))
        assert 2 <= done < long
        # rerun with a retry: killed again, Ray restarts it and it resumes from the folder
        driver = pool.submit(run_ray, [trial], BackendSettings(retries=1))
        _kill_trial_worker(run_dir, done + 2)
        (result,) = driver.result(timeout=120)
    assert done + 2 <= result.resumed_from < long
    assert result.episodes == long
    rows = _metrics(run_dir)
    assert len(rows) == long
    # as an uninterrupted run would be
    assert rows[:EPISODES] == _metrics(local_reference / "rpe" / "seed-0")


def test_trials_on_one_rig_run_there_one_at_a_time(cluster, tmp_path):
    # the twin standing in for rig ergo1: two trials that both need it, 2 CPUs free
    cid = campaign_id(tmp_path)
    trials = [
        Trial.of(str(tmp_path / "rpe" / f"seed-{s}"), "rpe", s, 8, campaign_id=cid,
              resources={"rig:ergo1": 1.0})
        for s in (0, 1)
    ]  # fmt: skip
    a, b = sorted(run_ray(trials, BackendSettings()), key=lambda r: r.started)
    assert a.episodes == b.episodes == 8
    assert a.finished <= b.started  # never both at once


def test_a_rig_trial_finds_its_calibration_by_rig_id_on_the_worker(
    cluster, calibration_dir, tmp_path, capsys
):
    # scheduled on the node with rig:ergo1, whose calibration folder has no ergo1/arena.json
    args = ["experiment", "--strategies", "rpe", "--episodes", "5", "--out", str(tmp_path / "c"),
            "--no-progress", "--backend", "ray", "--rig", "dynamixel", "--rig-id", "ergo1",
            "--port", "/dev/null"]  # fmt: skip
    assert main(args) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert str(calibration_dir / "ergo1" / "arena.json") in err
    assert "ergo calibrate arena --rig-id ergo1" in err
    assert not (tmp_path / "c" / "rpe" / "seed-0").exists()  # nothing started


def test_a_trial_needing_a_rig_no_node_has_is_refused_in_one_line(cluster, tmp_path, capsys):
    args = ["experiment", "--strategies", "rpe", "--episodes", "5", "--out", str(tmp_path / "c"),
            "--no-progress", "--backend", "ray", "--rig", "dynamixel", "--rig-id", "ergo2",
            "--port", "/dev/ttyUSB0"]  # fmt: skip
    t0 = time.monotonic()
    assert main(args) == 2
    assert time.monotonic() - t0 < 10  # refused, not left pending
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert "ergo2" in err and """--resources '{"rig:ergo2": 1}'""" in err


def test_rig_resources_of_a_trial_and_the_cluster_checks():
    assert trial_resources({"name": "sim", "rig_id": "twin", "options": {}}) == {}
    assert trial_resources({"name": "dynamixel", "rig_id": "ergo1", "options": {}}) == {
        "rig:ergo1": 1.0
    }
    t = Trial.of("/x/rpe/seed-0", "rpe", 0, 5, resources={"rig:ergo1": 1.0})
    check_rig_resources([t], {"CPU": 2.0, "rig:ergo1": 1.0})
    with pytest.raises(CampaignError, match="no Ray node has rig 'ergo1'"):
        check_rig_resources([t], {"CPU": 2.0})
    with pytest.raises(CampaignError, match="rig:ergo1 = 2 in all"):
        check_rig_resources([t], {"CPU": 2.0, "rig:ergo1": 2.0})


def test_the_local_backend_runs_one_arm_one_trial_at_a_time(tmp_path, capsys):
    args = ["experiment", "--strategies", "rpe", "--seeds", "0,1", "--episodes", "5",
            "--out", str(tmp_path / "c"), "--rig", "dynamixel", "--rig-id", "ergo1",
            "--jobs", "2"]  # fmt: skip
    assert main(args) == 2
    assert "one at a time" in capsys.readouterr().err


def test_a_worker_that_sees_another_campaign_folder_refuses(tmp_path):
    campaign_id(tmp_path)
    trial = Trial.of(str(tmp_path / "rpe" / "seed-0"), "rpe", 0, 5, campaign_id="not-this-one")
    with pytest.raises(CampaignError, match="same path"):
        run_trial(trial)
    assert not Path(trial.run_dir).exists()


def test_without_ray_the_ray_backend_says_how_to_install_it(tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)  # `import ray` raises ImportError
    args = ["experiment", "--strategies", "rpe", "--episodes", "5", "--out", str(tmp_path / "c"),
            "--no-progress", "--backend", "ray"]  # fmt: skip
    assert main(args) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "pip install 'ergo-explore[ray]'" in err
