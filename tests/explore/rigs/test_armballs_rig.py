"""The ``armballs`` and ``arm2balls`` rigs behind the Rig interface: every strategy on both, the
published preset, determinism, resume after SIGKILL, what the records hold."""

from __future__ import annotations

import csv
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch

from explore.campaigns.trial import Trial, run_trial
from explore.cli import main
from explore.learner.strategies.registry import preset_options
from explore.runs.layout import HISTORY_FILE, METRICS_FILE
from explore.runs.metrics import read_metrics
from explore.runs.store import RunStore, read_synced
from sim.armballs.render import pixel_to_world

torch.set_num_threads(1)
ROOT = Path(__file__).resolve().parents[3]
N = 50
RIGS = ("armballs", "arm2balls")
STRATEGIES = (
    "rpe", "rge-efr", "mge-efr", "rge-vae", "mge-vae", "rge-betavae", "mge-betavae", "rge-sae",
    "mge-sae", "rge-online",
)  # fmt: skip
BOOTSTRAP = 10


@pytest.fixture(scope="module")
def models(tmp_path_factory) -> dict[str, str]:
    """An untrained VAE (latents ranked by a made-up KL) and spatial autoencoder: enough to
    run the strategies; what they learn is not what is tested here."""
    from testkit.untrained_models import save_untrained_models

    return save_untrained_models(tmp_path_factory.mktemp("models"))


def strategy_options(strategy: str, models: dict[str, str], preset: bool) -> dict:
    opts = preset_options("corl2018", strategy) if preset else {}
    if strategy != "rpe":
        opts["bootstrap"] = BOOTSTRAP
    if "vae" in strategy:
        opts["vae"] = models["vae"]
    if "sae" in strategy:
        opts["sae"] = models["sae"]
    if strategy == "rge-online":
        opts.update(vae_iterations=2)
    return opts


def rig(name: str) -> dict:
    return {"name": name, "rig_id": "twin", "options": {}}


def run(out: Path, strategy: str, opts: dict, rig_name: str, episodes: int, seed: int = 0):
    run_trial(Trial.of(str(out), strategy, seed, episodes, opts, rig(rig_name)))
    return RunStore.open(out).records


@pytest.mark.parametrize("rig_name", RIGS)
@pytest.mark.parametrize("strategy", STRATEGIES)
def test_every_strategy_runs_50_iterations_on_both_rigs(strategy, rig_name, models, tmp_path):
    preset = rig_name == "arm2balls"  # the published settings there, our defaults on armballs
    recs = run(tmp_path / "r", strategy, strategy_options(strategy, models, preset), rig_name, N)
    assert [r.episode for r in recs] == list(range(N))
    for r in recs:
        assert r.theta.shape == (49,) and np.all(np.abs(r.theta) <= 1)
        assert r.image.shape == (64, 64, 3) and r.image.dtype == np.uint8
        assert r.targets.shape == (50, 7) and r.end_effector.shape == (50, 3)
        assert np.all(np.abs(r.ball) <= 1) and r.sim_state.size == 0
        assert np.all(np.isfinite(r.distractor)) == (rig_name == "arm2balls")
    later = recs[BOOTSTRAP:] if strategy != "rge-online" else recs[12:]
    if strategy == "rpe":
        assert {r.kind for r in recs} == {"random"}
    elif strategy != "rge-online":
        assert {r.kind for r in later} <= {"explore", "exploit", "random"}
        assert sum(r.kind in ("explore", "exploit") for r in later) >= len(later) // 2
    m = read_metrics(tmp_path / "r" / METRICS_FILE)
    assert list(m["episode"]) == list(range(N)) and m["ball_cells"][-1] >= 1


def test_the_published_preset_cycles_four_noisy_episodes_and_one_exploit_per_goal(tmp_path):
    opts = {**preset_options("corl2018", "mge-efr"), "bootstrap": 20}
    recs = run(tmp_path / "r", "mge-efr", opts, "arm2balls", 120)
    goal_directed = recs[20:]
    rest = recs[0].ball
    ball_moved = any(not np.array_equal(r.ball, rest) for r in recs[:20])
    for start in range(0, len(goal_directed), 5):
        cycle = goal_directed[start : start + 5]
        assert [r.kind for r in cycle] == ["explore"] * 4 + ["exploit"]
        assert len({r.module for r in cycle}) == 1
        assert all(np.array_equal(r.goal, cycle[0].goal) for r in cycle)
        assert cycle[0].goal.shape == (2,) and np.all(np.abs(cycle[0].goal) <= 1)
        # the noisy episodes vary one set of parameters by sigma 0.05 (clipped to [-1, 1]),
        # except in a ball module that has seen the ball at rest only (uniform parameters:
        # test_a_module_that_saw_one_outcome_plays_uniform_parameters_in_the_preset)
        if cycle[0].module == 1 or ball_moved:
            thetas = np.array([r.theta for r in cycle[:4]])
            assert np.max(np.abs(thetas - thetas.mean(axis=0))) < 0.3
        ball_moved = ball_moved or any(not np.array_equal(r.ball, rest) for r in cycle)
    # two modules (ball, distractor), no hand; RGE-EFR: (ball, distractor) as one 4-D goal
    assert {r.module for r in goal_directed} == {0, 1}
    rge = run(tmp_path / "g", "rge-efr", {**preset_options("corl2018", "rge-efr"),
                                         "bootstrap": 20}, "arm2balls", 40)  # fmt: skip
    assert {r.goal.shape for r in rge[20:]} == {(4,)}


def _published_config() -> dict[str, dict[str, str]]:
    with open(ROOT / "docs" / "armballs_published_config.csv", newline="") as f:
        return {row["algorithm"]: row for row in csv.DictReader(f)}


@pytest.mark.parametrize(
    "strategy, algorithm",
    [("rge-efr", "RGE-EFR"), ("mge-efr", "MGE-EFR"), ("rge-vae", "RGE-VAE"),
     ("mge-vae", "MGE-VAE"), ("rge-betavae", "RGE-betaVAE"), ("mge-betavae", "MGE-betaVAE")],
)  # fmt: skip
def test_the_preset_s_settings_are_what_the_published_config_says(strategy, algorithm, models):
    from explore.learner.strategies import make_strategy
    from explore.learner.strategies.goal_exploration import NORMAL_CLIP
    from explore.rigs.armballs import ARM_2_BALLS_SQUARE

    published = _published_config()[algorithm]
    opts = preset_options("corl2018", strategy)
    assert opts["bootstrap"] == int(published["n_bootstrap"])
    assert opts["sigma"] == float(published["explo_noise_sdev"])
    assert opts["random_choice"] == float(published["explo_ratio"])
    assert opts["n_explore"] == int(published["n_explore"]) and opts["schedule"] == "cycle"
    assert str(opts["window"]) in published["win_size"].split()
    assert opts["random_episodes"] == 0 and opts["interest"] == "exponential"
    assert opts["competence"] == "distance"
    # explauto's NonParametric, the original's inverse model (docs/results_armballs.md, stalls)
    assert opts["one_outcome"] == "random" and opts["ties"] == "spread"
    goals = {"uniform": "box", "normal": "normal"}[published["interest_model"]]
    assert opts["goals"] == goals
    if goals == "normal":
        assert float(published["s_bound"]) == NORMAL_CLIP
    if "vae" in strategy:
        opts["vae"] = models["vae"]
    s = make_strategy(strategy, n_params=49, scene=ARM_2_BALLS_SQUARE, **opts)
    sizes = [len(m) for m in s.space.modules]
    if published["representation"] == "flat":
        assert sizes == [4]  # (distractor, ball) as one goal
    elif published["representation"] == "modular":
        assert sizes == [2, 2]  # one module per ball, no hand module
    else:
        n_latents, n_modules = int(published["n_latents"]), int(published["n_modules"])
        assert sizes == [n_latents // n_modules] * n_modules
    assert s.policy.context_dim == 0  # the scene resets: no context, as the original


def test_a_run_is_deterministic_for_a_seed_and_resumes_identically_at_any_point(tmp_path):
    opts = {**preset_options("corl2018", "mge-efr"), "bootstrap": 20}
    ref = run(tmp_path / "ref", "mge-efr", opts, "arm2balls", 60, seed=3)
    again = run(tmp_path / "again", "mge-efr", opts, "arm2balls", 60, seed=3)
    assert all(a.equals(b) for a, b in zip(ref, again, strict=True))
    other = run(tmp_path / "other", "mge-efr", opts, "arm2balls", 25, seed=4)
    assert not np.array_equal(other[0].theta, ref[0].theta)
    assert not np.array_equal(other[0].distractor, ref[0].distractor)
    for cut in (20, 21, 22, 23, 24, 25):  # every position of a goal's cycle
        out = tmp_path / f"cut-{cut}"
        run(out, "mge-efr", opts, "arm2balls", cut, seed=3)
        resumed = run(out, "mge-efr", opts, "arm2balls", 60, seed=3)
        assert all(a.equals(b) for a, b in zip(ref, resumed, strict=True)), cut


def test_a_run_killed_with_sigkill_or_a_power_cut_resumes_to_the_same_history(
    tmp_path, explore_killed_at
):
    """The history fsyncs at most once a second here (``SYNC_INTERVAL_S``). A SIGKILL loses
    nothing that was appended (it is in the page cache); a power cut may lose what was written
    after the last fsync, in any shape (``tests/explore/runs/test_store.py``): modelled here
    by the first record past ``history.synced`` missing on disk and the later ones kept. Both
    resume to the uninterrupted history."""
    args = ["--rig", "arm2balls", "--strategy", "mge-efr", "--preset", "corl2018",
            "--strategy-option", "bootstrap=50", "--episodes", "4000", "--seed", "5",
            "--rerun", "off", "--no-progress"]  # fmt: skip
    ref = tmp_path / "ref"
    assert main(["explore", *args, "--out", str(ref)]) == 0
    out = tmp_path / "killed"
    explore_killed_at(args, out, 600_000)
    hist = out / HISTORY_FILE
    data = hist.read_bytes()
    synced = read_synced(out)
    assert synced is not None and 0 < synced <= len(data)
    power_cut = tmp_path / "power-cut"
    shutil.copytree(out, power_cut)
    with RunStore.open(out) as killed:  # every record it flushed is there
        done = len(killed)
    assert 0 < done < 4000, f"kill landed outside the run ({done} episodes)"
    if synced < len(data):  # the disk lost the first record past the last fsync
        damaged = bytearray(data)
        end = min(len(data), synced + 12 + int.from_bytes(data[synced + 4 : synced + 8], "little"))
        damaged[synced:end] = bytes(end - synced)
        (power_cut / HISTORY_FILE).write_bytes(bytes(damaged))
    with RunStore.open(power_cut) as cut:  # cut at the first record the disk lost
        assert len(cut) <= done and cut.history_path.stat().st_size == synced
    a = RunStore.open(ref).records
    for run in (out, power_cut):
        assert main(["explore", "--resume", str(run), "--rerun", "off", "--no-progress"]) == 0
        b = RunStore.open(run).records
        assert len(a) == len(b) and all(x.equals(y) for x, y in zip(a, b, strict=True))
        assert list(read_metrics(run / METRICS_FILE)["episode"]) == list(range(4000))


def test_records_hold_bgr_images_showing_the_balls_where_the_record_says(tmp_path):
    recs = run(tmp_path / "r", "rpe", {}, "arm2balls", 300)
    caught = [r for r in recs if r.ball_moved]
    assert caught, "no ball caught in 300 random episodes (about 2% are)"
    for r in [*caught[:3], recs[0]]:
        b, g, red = (r.image[..., c].astype(int) for c in range(3))
        for mask, where in (
            ((red > 128) & (g > 128) & (b < 64), r.ball),  # yellow ball
            ((b > 128) & (red < 64) & (g < 64), r.distractor),
        ):  # blue
            rows, cols = np.nonzero(mask)
            if len(rows) < 20:  # hidden under the other ball
                continue
            # the disc's visible part: its centroid is within its radius (5.4 px) of the state
            centre = pixel_to_world(np.array([cols.mean(), rows.mean()]), 64)
            assert np.linalg.norm(centre - where) < 0.17, (r.episode, centre, where)
    assert np.allclose(recs[0].context_ball, [0.6, 0.6])
    assert np.allclose(recs[0].context_distractor, [0.7, -0.45])


def test_the_metric_is_the_published_exploration_ratio_on_the_square(tmp_path):
    from explore.runs.metrics import checkpoints, exploration_ratio

    recs = run(tmp_path / "r", "rpe", {}, "armballs", 400)
    m = read_metrics(tmp_path / "r" / METRICS_FILE)
    finals = np.array([r.ball for r in recs])
    # the published binning: 30 x 30 cells of [-1, 1]^2 (points on an edge go to the upper cell)
    cells = {tuple(np.floor((p + 1) / 2 * 30).astype(int).clip(0, 29)) for p in finals}
    assert m["ball_cells"][-1] == len(cells)
    assert list(checkpoints()[:4]) == [0, 333, 666, 1000] and checkpoints()[-1] == 9666
    ratio = exploration_ratio(m["ball_cells"], np.array([0, 1, 333, 400, 401]))
    assert ratio[0] == 0 and ratio[1] == 1 / 900 and np.isnan(ratio[-1])
    assert ratio[3] == len(cells) / 900


def test_rig_outcome_datasets_spread_both_balls_over_the_square(tmp_path):
    out = tmp_path / "d.npz"
    assert main(["dataset", "outcomes", "--rig", "arm2balls", "--n", "500", "--out", str(out),
                 "--no-progress"]) == 0  # fmt: skip
    with np.load(out) as z:
        images, ball, distractor = z["images"], z["ball"], z["distractor"]
    assert images.shape == (500, 64, 64, 3) and images.dtype == np.uint8
    for xy in (ball, distractor):
        assert np.all(np.abs(xy) <= 1) and np.all(np.abs(xy.mean(axis=0)) < 0.1)
        assert np.all(xy.std(axis=0) > 0.5)  # uniform over [-1, 1]: sd 0.577
    # BGR: the yellow ball has no blue, the blue distractor no red
    assert images[..., 2].max() == 255 and images[..., 0].max() == 255
    assert main(["dataset", "outcomes", "--rig", "armballs", "--n", "5", "--distractor",
                 "--out", str(out)]) == 2  # fmt: skip


def _blind_ball_cycles(records) -> tuple[list[float], list[float]]:
    """Spread (sd) of the noisy parameters of each goal cycle of the ball's module (module 0),
    split by whether the ball had ever left its start when the cycle began."""
    start = records[0].ball
    blind, seeing, varied = [], [], False
    goal_directed = [r for r in records if r.module >= 0]
    first = records.index(goal_directed[0])
    varied = any(not np.array_equal(r.ball, start) for r in records[:first])
    for c in range(0, len(goal_directed) - 4, 5):
        cycle = goal_directed[c : c + 5]
        if cycle[0].module == 0:
            spread = float(np.std(np.diff([r.theta for r in cycle[:4]], axis=0)))
            (seeing if varied else blind).append(spread)
        varied = varied or any(not np.array_equal(r.ball, start) for r in cycle)
    return blind, seeing


def test_a_module_that_saw_one_outcome_plays_uniform_parameters_in_the_preset(tmp_path):
    opts = {**preset_options("corl2018", "mge-efr"), "bootstrap": 5}
    records = run(tmp_path / "random", "mge-efr", opts, "arm2balls", 150, seed=3)
    blind, seeing = _blind_ball_cycles(records)
    assert len(blind) >= 1  # the ball lay still through the bootstrap and a cycle or more
    assert min(blind) > 0.5  # independent uniform draws in [-1, 1]: sd of a difference 0.82
    assert all(s < 0.15 for s in seeing)  # afterwards: one base, noise 0.05
    nearest = run(tmp_path / "nearest", "mge-efr", {**opts, "one_outcome": "nearest"},
                  "arm2balls", 150, seed=3)  # fmt: skip
    blind, _ = _blind_ball_cycles(nearest)
    assert blind and max(blind) < 0.15  # the earliest episode, varied by the noise
    for cut in (23, 24, 25, 26, 27):  # resumed anywhere in a cycle: the same history
        out = tmp_path / f"cut-{cut}"
        run(out, "mge-efr", opts, "arm2balls", cut, seed=3)
        resumed = run(out, "mge-efr", opts, "arm2balls", 150, seed=3)
        assert all(a.equals(b) for a, b in zip(records, resumed, strict=True)), cut
