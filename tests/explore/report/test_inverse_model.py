"""The inverse-model diagnosis (testkit/inverse_model.py,
experiments/diagnose_inverse_model.py) re-finds the neighbour the meta-policy really used."""

from __future__ import annotations

import pytest
import torch

from explore.campaigns.trial import run_one
from testkit.inverse_model import PAIRS, DiagnosisError, diagnose, figure
from vision.vae import Vae, VaeConfig

torch.set_num_threads(1)


@pytest.mark.parametrize(
    "strategy, extra",
    [("rge-efr", {}), ("rge-efr", {"form": "polar"}), ("mge-efr", {}), ("rge-vae", {})],
)
def test_the_neighbour_found_again_is_the_one_whose_parameters_were_played(
    strategy, extra, tmp_path
):
    # with the exploration noise off, a goal episode plays its neighbour's theta exactly: the
    # diagnostic's |theta_k - theta_j| is 0 only if it found the same neighbour (the bootstrap's
    # thetas are distinct random draws)
    # stall_window 0: no random episodes at all (the ball rarely moves in 30 episodes)
    opts = {"bootstrap": 12, "random_episodes": 0, "stall_window": 0, "sigma": 0.0, **extra}
    if strategy == "rge-vae":
        torch.manual_seed(0)
        opts["vae"] = str(Vae(VaeConfig()).save(tmp_path / "vae"))
    run_one(str(tmp_path / "run"), strategy, opts, 0, 30, False)
    arrays: dict = {}
    d = diagnose(tmp_path / "run", arrays=arrays)
    assert d["goal_episodes"] == 18
    assert d["theta_gap"] == 0.0
    assert 0.0 <= d["new_cell"] <= 1.0 and d["start_gap_m"] >= 0.0
    assert arrays["start_gap"].shape == (18,)
    assert arrays["pair_space"].shape == arrays["pair_arena"].shape == (PAIRS,)
    figure({strategy: arrays}, tmp_path / "diag.png")
    assert (tmp_path / "diag.png").read_bytes()[:4] == b"\x89PNG"


def test_a_run_without_an_inverse_model_is_a_one_line_error(tmp_path):
    run_one(str(tmp_path / "rpe"), "rpe", {}, 0, 3, False)
    with pytest.raises(DiagnosisError, match="'rpe' has no inverse model"):
        diagnose(tmp_path / "rpe")


def test_the_neighbour_is_found_again_among_tied_episodes_as_the_run_picked_it(tmp_path):
    # Arm-2-Balls resets its scene: every episode that missed the ball has the same ball outcome, so
    # goals meet many equally near episodes; with ties "spread" the run picks one of them by a
    # hash of the query, and the diagnosis must pick the same (sigma 0: the same theta)
    from explore.campaigns.trial import Trial, run_trial
    from explore.learner.strategies.registry import preset_options

    opts = {**preset_options("corl2018", "mge-efr"), "bootstrap": 10, "sigma": 0.0,
            "one_outcome": "nearest"}  # fmt: skip
    assert opts["ties"] == "spread"
    rig = {"name": "arm2balls", "rig_id": "twin", "options": {}}
    run_trial(Trial.of(str(tmp_path / "run"), "mge-efr", 0, 60, opts, rig))
    d = diagnose(tmp_path / "run")
    assert d["goal_episodes"] == 50
    assert d["theta_gap"] == 0.0
