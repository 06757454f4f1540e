"""Goal exploration in learned (VAE) goal spaces on the twin: pre-trained and online."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from explore.campaigns.trial import run_one
from explore.rigs.arena import TWIN_ARENA
from explore.runs.store import RunStore
from vision.vae import Vae, VaeConfig

torch.set_num_threads(1)


@pytest.fixture(scope="module")
def vae_dir(tmp_path_factory):
    torch.manual_seed(0)
    vae = Vae(VaeConfig())
    vae.config.kl_per_latent = [float(v) for v in np.arange(10)[::-1]]
    return vae.save(tmp_path_factory.mktemp("vae") / "model")


def test_mge_vae_runs_with_modules_ranked_by_kl(vae_dir, tmp_path):
    out = tmp_path / "mge"
    opts = {"vae": str(vae_dir), "bootstrap": 10, "random_episodes": 0, "stall_window": 0}
    run_one(str(out), "mge-vae", opts, 0, 30, False)
    recs = RunStore.open(out).records
    later = recs[10:]
    assert all(r.kind in ("explore", "exploit") for r in later)
    assert all(0 <= r.module < 5 and r.goal.shape == (2,) for r in later)


def test_online_variant_trains_after_bootstrap_and_resumes_identically(tmp_path):
    opts = {"bootstrap": 12, "vae_iterations": 4, "random_episodes": 0, "stall_window": 0}
    a, b = tmp_path / "a", tmp_path / "b"
    run_one(str(a), "rge-online", opts, 1, 20, False)
    run_one(str(b), "rge-online", opts, 1, 15, False)
    run_one(str(b), "rge-online", opts, 1, 20, False)  # replays the bootstrap: retrains the VAE
    ra, rb = RunStore.open(a).records, RunStore.open(b).records
    assert [r.kind for r in ra[12:]] == ["explore"] * 8
    assert all(r.goal.shape == (10,) for r in ra[12:])
    assert all(x.equals(y) for x, y in zip(ra, rb, strict=True))


def test_zscored_latents_use_the_statistics_saved_with_the_vae(vae_dir, tmp_path):
    from explore.learner.strategies import make_strategy
    from explore.learner.strategies.base import StrategyError
    from vision.vae import load_vae

    with pytest.raises(StrategyError, match="no latent statistics"):
        make_strategy("rge-vae", scene=TWIN_ARENA, vae=str(vae_dir), latents="zscore")
    with pytest.raises(StrategyError, match="latents must be one of"):
        make_strategy("rge-vae", scene=TWIN_ARENA, vae=str(vae_dir), latents="whitened")
    vae = load_vae(vae_dir)
    images = np.random.default_rng(0).integers(0, 256, (6, 64, 64, 3), dtype=np.uint8)
    vae.config.latent_mean, vae.config.latent_std = vae.latent_stats(images)
    folder = vae.save(tmp_path / "with-stats")
    raw = make_strategy("rge-vae", scene=TWIN_ARENA, vae=str(folder)).space
    z = make_strategy("rge-vae", scene=TWIN_ARENA, vae=str(folder), latents="zscore").space

    class Rec:
        image = images[2]

    mean, std = np.array(vae.config.latent_mean), np.array(vae.config.latent_std)
    assert np.allclose(z.outcome(Rec), (raw.outcome(Rec) - mean) / std)
    zs = np.stack([z.outcome(type("R", (), {"image": im})) for im in images])
    assert np.allclose(zs.mean(axis=0), 0.0, atol=1e-4)  # float32 encodings
    assert np.allclose(zs.std(axis=0), 1.0, atol=1e-4)


def test_online_vae_options_are_checked_before_the_bootstrap():
    from explore.learner.strategies import make_strategy
    from explore.learner.strategies.base import StrategyError

    for bad in ({"vae_beta": -1}, {"vae_iterations": 0}):
        with pytest.raises(StrategyError, match="rge-online: bad VAE option"):
            make_strategy("rge-online", scene=TWIN_ARENA, **bad)
    with pytest.raises(StrategyError, match="option vae_capacity must be a number or null"):
        make_strategy("rge-online", scene=TWIN_ARENA, vae_capacity="lots")
    plain, _ = make_strategy("rge-online", scene=TWIN_ARENA, vae_capacity=None, vae_beta=1)._configs
    assert plain.capacity is None and plain.beta == 1.0
    default, train = make_strategy(
        "rge-online", scene=TWIN_ARENA
    )._configs  # the pre-trained VAE's schedule
    assert (default.beta, default.capacity, default.capacity_iterations) == (10.0, 10.0, 500)
    assert train.iterations == 700


def test_online_vae_takes_the_training_aids_of_the_recipe(tmp_path):
    from explore.learner.strategies import make_strategy
    from explore.learner.strategies.base import StrategyError

    recipe = {
        "vae_iterations": 3000, "vae_lr_final": 1e-5, "vae_channels_last": True,
        "vae_mean_image_offset": True, "vae_kl_delay": 1000, "vae_kl_warmup": 1000,
    }  # fmt: skip
    model, train = make_strategy("rge-online", scene=TWIN_ARENA, **recipe)._configs
    assert (model.mean_image_offset, model.kl_delay, model.kl_warmup) == (True, 1000, 1000)
    assert (train.iterations, train.lr, train.lr_final, train.channels_last) == (
        3000, 1e-3, 1e-5, True,
    )  # fmt: skip
    default_model, default_train = make_strategy("rge-online", scene=TWIN_ARENA)._configs
    assert not default_model.mean_image_offset and default_model.kl_delay == 0
    assert default_train.lr_final is None and not default_train.channels_last
    for bad in ({"vae_lr_final": 1e-2}, {"vae_kl_delay": -1}, {"vae_lr": 0}):
        with pytest.raises(StrategyError, match="rge-online: bad VAE option"):
            make_strategy("rge-online", scene=TWIN_ARENA, **bad)
    # a short run with every aid trains after its bootstrap and resumes identically
    opts = {
        "bootstrap": 12, "vae_iterations": 4, "random_episodes": 0, "stall_window": 0,
        **{**recipe, "vae_iterations": 4, "vae_kl_delay": 2, "vae_kl_warmup": 1},
    }  # fmt: skip
    a, b = tmp_path / "a", tmp_path / "b"
    run_one(str(a), "rge-online", opts, 2, 16, False)
    run_one(str(b), "rge-online", opts, 2, 14, False)
    run_one(str(b), "rge-online", opts, 2, 16, False)
    ra, rb = RunStore.open(a).records, RunStore.open(b).records
    assert [r.kind for r in ra[12:]] == ["explore"] * 4
    assert all(x.equals(y) for x, y in zip(ra, rb, strict=True))
