"""``ergo experiment``: a tiny campaign writes its summary and resumes without re-running."""

from __future__ import annotations

import csv

import pytest

from explore.cli import main
from explore.runs.config import CHANGED_STRATEGY_DEFAULTS
from explore.runs.layout import HISTORY_FILE, METRICS_FILE, RUN_FILE, TRIAL_FILE


def _summary(out):
    with open(out / "summary.csv", newline="") as f:
        return list(csv.DictReader(f))


def test_tiny_campaign_writes_summary_and_skips_finished_runs(tmp_path, capsys):
    out = tmp_path / "campaign"
    args = ["experiment", "--strategies", "rpe,rge-efr", "--seeds", "0-0", "--episodes", "20",
            "--out", str(out), "--option", "bootstrap=10", "--no-progress"]  # fmt: skip
    assert main(args) == 0
    rows = _summary(out)
    assert [r["strategy"] for r in rows] == ["rpe", "rge-efr"]
    assert all(int(r["episodes"]) == 20 and float(r["cells_mean"]) >= 1 for r in rows)
    assert "welch_p_vs_rpe" in rows[1]  # one seed: no test, written as nan
    assert "rge-efr" in capsys.readouterr().out
    report = out / "report"  # written at the end from metrics.csv: curves, summary with Welch
    assert {p.name for p in report.iterdir()} == {
        "campaign_coverage.png", "summary.md", "summary.html"
    }  # fmt: skip
    assert "Welch p vs rpe" in (report / "summary.md").read_text()
    hist = out / "rge-efr" / "seed-0" / HISTORY_FILE
    stamp = hist.stat().st_mtime_ns, hist.stat().st_size
    assert main(args) == 0  # finished: skipped
    assert (hist.stat().st_mtime_ns, hist.stat().st_size) == stamp
    # an unfinished run is resumed (extended), the finished one is not touched
    assert main([*args[:6], "25", *args[7:]]) == 0
    rows = _summary(out)
    assert all(int(r["episodes"]) == 25 for r in rows)


def test_an_option_can_go_to_one_strategy_of_the_campaign(tmp_path, capsys):
    import json

    out = tmp_path / "campaign"
    args = ["experiment", "--strategies", "rpe,rge-efr,mge-efr", "--seeds", "0-0", "--episodes",
            "12", "--out", str(out), "--option", "bootstrap=10", "--option", "rge-efr:form=polar",
            "--no-progress"]  # fmt: skip
    assert main(args) == 0

    def options(strategy: str) -> dict:
        """The options given (an option whose default changed is written out too, as today's
        default: tests/explore/runs/test_changed_defaults.py)."""
        run = json.loads((out / strategy / "seed-0" / RUN_FILE).read_text())
        given = run["config"]["strategy"]["options"]
        return {k: v for k, v in given.items() if k not in CHANGED_STRATEGY_DEFAULTS}

    assert options("rpe") == {}
    assert options("rge-efr") == {"bootstrap": 10, "form": "polar"}
    assert options("mge-efr") == {"bootstrap": 10}
    bad = [*args[:-1], "--option", "rge-vae:latents=zscore", "--no-progress"]
    assert main(bad) == 2
    assert "'rge-vae' is not a strategy of this campaign" in capsys.readouterr().err


@pytest.mark.parametrize(
    "option, said",
    [("stall_window=\"x\"", "--option stall_window must be an integer"),
     ("nosuch=1", "--option nosuch is unknown; known: ")],
)  # fmt: skip
def test_a_bad_option_is_one_line_naming_it_and_nothing_is_written(tmp_path, capsys, option, said):
    out = tmp_path / "c"
    code = main(["experiment", "--strategies", "rge-efr", "--seeds", "0-0", "--episodes", "2",
                 "--out", str(out), "--option", option, "--no-progress",
                 "--no-report"])  # fmt: skip
    err = capsys.readouterr().err
    assert code == 2 and said in err and err.count("\n") == 1, err
    assert "config." not in err and not out.exists()


def test_a_vae_strategy_without_a_model_names_the_command(tmp_path, capsys):
    code = main(["experiment", "--strategies", "rge-vae", "--episodes", "5",
                 "--out", str(tmp_path / "c"), "--no-progress"])  # fmt: skip
    assert code == 2
    err = capsys.readouterr().err
    assert "ergo vae train" in err and "ergo dataset outcomes" in err and err[-1] == "\n"
    assert err.count("\n") == 1


def test_welch_test_against_rpe_matches_the_formula():
    import math

    from explore.campaigns.stats import welch_vs_baseline

    a, b = [10.0, 12.0, 14.0], [1.0, 2.0, 3.0]  # variances 4 and 1, 3 seeds each
    t, p = welch_vs_baseline(a, b)
    assert math.isclose(t, (12.0 - 2.0) / math.sqrt(4 / 3 + 1 / 3), rel_tol=1e-12)
    assert 0 < p < 0.05
    t, p = welch_vs_baseline(b, a)
    assert t < 0 and 0 < p < 0.05  # two-sided: the same p the other way round
    assert welch_vs_baseline([5.0, 6.0], [5.0, 6.0])[1] == 1.0
    assert all(math.isnan(x) for x in welch_vs_baseline([5.0], [1.0, 2.0]))
    assert all(math.isnan(x) for x in welch_vs_baseline([3.0, 3.0], [3.0, 3.0]))


def _alive(pid: int) -> bool:
    """Whether ``pid`` runs (a zombie, dead but not reaped, counts as ended)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False


def test_a_campaign_killed_with_sigkill_leaves_no_worker_running(tmp_path):
    """Its workers end with it (they would run their trials on and hold the trial locks
    against the rerun), and the rerun resumes the trials."""
    import json
    import os
    import signal
    import subprocess
    import sys
    import time

    out = tmp_path / "campaign"
    # 200 episodes: twin episodes are fast enough (no fsync each) that one trial could end 80
    # before the other had started
    args = ["experiment", "--strategies", "rpe", "--seeds", "0,1", "--episodes", "200",
            "--out", str(out), "--jobs", "2", "--no-progress"]  # fmt: skip
    driver = subprocess.Popen([sys.executable, "-m", "explore.cli", *args],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)  # fmt: skip
    trials = [out / "rpe" / f"seed-{s}" for s in (0, 1)]
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and not all(
        (t / METRICS_FILE).exists() and len((t / METRICS_FILE).read_text().splitlines()) > 3
        for t in trials
    ):
        time.sleep(0.05)
    workers = [json.loads((t / TRIAL_FILE).read_text())["pid"] for t in trials]
    assert driver.pid not in workers and all(_alive(p) for p in workers)
    os.kill(driver.pid, signal.SIGKILL)
    driver.wait()
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline and any(_alive(p) for p in workers):
        time.sleep(0.05)
    assert not any(_alive(p) for p in workers), "a worker outlived its campaign"
    left = [len((t / METRICS_FILE).read_text().splitlines()) - 1 for t in trials]
    assert all(0 < n < 200 for n in left), left
    assert main(args) == 0  # resumes both
    rows = _summary(out)
    assert [int(r["episodes"]) for r in rows] == [200]


def test_seeds_are_a_count_a_list_or_a_range_as_the_issue_writes_them():
    from explore.cli.experiment import parse_seeds
    from plumbing.cli_errors import CliError

    assert parse_seeds("8") == list(range(8))  # `--seeds 8`: eight seeds
    assert parse_seeds("0,2,5") == [0, 2, 5]
    assert parse_seeds("3-5,0") == [3, 4, 5, 0]
    assert parse_seeds("4-4") == [4]
    for bad, says in (("0", "at least 1"), ("5-3", "empty range"), ("a", "count, a list")):
        with pytest.raises(CliError, match=says):
            parse_seeds(bad)


def test_workers_is_another_name_for_jobs(tmp_path):
    import argparse

    from explore.cli import experiment as cli_experiment

    parser = argparse.ArgumentParser()
    cli_experiment.register(parser.add_subparsers())
    args = parser.parse_args(["experiment", "--strategies", "rpe", "--seeds", "8", "--episodes",
                              "5", "--workers", "2", "--out", str(tmp_path)])  # fmt: skip
    assert args.jobs == 2 and cli_experiment.parse_seeds(args.seeds) == list(range(8))


def test_two_campaign_processes_on_one_campaign_say_what_happened(tmp_path):
    """Two ``ergo experiment`` on one campaign folder: a trial whose run the other process is
    writing is waited for, then found complete (or resumed, had the other died); both end
    with every run complete and exit 0. Before: both exited 2 with "trial(s) failed" although
    every run had completed."""
    import subprocess
    import sys

    from explore.runs.store import read_history

    out = tmp_path / "c"
    cmd = [sys.executable, "-m", "explore.cli", "experiment", "--strategies", "rpe",
           "--seeds", "0,1", "--episodes", "25", "--out", str(out), "--no-progress",
           "--no-report"]  # fmt: skip
    procs = [subprocess.Popen(cmd, stderr=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
             for _ in range(2)]  # fmt: skip
    outs = [p.communicate(timeout=300) for p in procs]
    for p, (_, stderr) in zip(procs, outs, strict=True):
        assert p.returncode == 0, stderr
        assert "failed" not in stderr and "Traceback" not in stderr, stderr
    for seed in (0, 1):
        history = read_history(out / "rpe" / f"seed-{seed}")  # checks: no duplicate
        assert [r.episode for r in history.records] == list(range(25))


def test_processes_starting_one_campaign_at_once_agree_on_its_id(tmp_path):
    """Eight threads ask for the id of a campaign folder that has none, 20 times over: each
    time all get the one id the folder's campaign.json holds (before: each could write its
    own, and two ergo experiment on one folder then disagreed on whose runs they were)."""
    import threading

    from explore.campaigns.plan import campaign_id
    from explore.campaigns.trial import CAMPAIGN_FILE, read_json

    for k in range(20):
        out = tmp_path / f"c{k}"
        start = threading.Barrier(8)
        ids: list[str] = []

        def ask(out=out, start=start, ids=ids) -> None:
            start.wait()
            ids.append(campaign_id(out))

        threads = [threading.Thread(target=ask) for _ in range(8)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        assert set(ids) == {read_json(out / CAMPAIGN_FILE)["id"]}
        assert sorted(p.name for p in out.iterdir()) == [CAMPAIGN_FILE]  # no file left behind


def test_extending_a_campaign_with_another_option_value_is_refused(tmp_path, capsys):
    out = tmp_path / "campaign"
    head = ["experiment", "--strategies", "rpe,rge-efr", "--seeds", "0-0", "--out", str(out),
            "--no-progress", "--no-report", "--episodes"]  # fmt: skip
    assert main([*head, "12", "--option", "bootstrap=10"]) == 0
    hist = out / "rge-efr" / "seed-0" / HISTORY_FILE
    stamp = hist.stat().st_mtime_ns, hist.stat().st_size
    for options, said in (
        (["--option", "bootstrap=8"], "bootstrap = 10, not 8"),
        (["--option", "bootstrap=10", "--option", "sigma=0.1"], "sigma = its default, not 0.1"),
    ):
        assert main([*head, "15", *options]) == 2
        err = capsys.readouterr().err
        assert said in err and "a run keeps the options it started with" in err
        assert len(err.strip().splitlines()) == 1
        assert (hist.stat().st_mtime_ns, hist.stat().st_size) == stamp  # nothing ran
    # the same options extend it, the option whose default changed (written out) included
    assert main([*head, "15", "--option", "bootstrap=10"]) == 0
    assert main([*head, "16", "--option", "bootstrap=10", "--option", "stall_window=10"]) == 0
    assert hist.stat().st_size > stamp[1]
