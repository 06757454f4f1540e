"""The spatial autoencoder: its code is where things are, it trains and resumes like the VAE,
and the selection criterion (held-out explained pixel variance) tells a trained model from a
collapsed one on synthetic images, without any label."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from vision.representation_quality import explained_pixel_variance, heldout_split
from vision.sae_train import train_sae
from vision.spatial_ae import (
    SaeConfig,
    SpatialAutoencoder,
    is_sae_folder,
    load_sae,
    spatial_softmax_xy,
)
from vision.vae import VaeError
from vision.vae_train import TrainConfig

torch.set_num_threads(1)


def disc_images(n: int, seed: int = 0, radius: float = 5.0) -> tuple[np.ndarray, np.ndarray]:
    """n BGR images (64, 64, 3) of a yellow disc on a blue floor at random centres, and the
    centres (n, 2) in pixels (x, y)."""
    rng = np.random.default_rng(seed)
    centres = rng.uniform(12, 52, (n, 2))
    ys, xs = np.mgrid[:64, :64]
    images = np.empty((n, 64, 64, 3), np.uint8)
    images[:] = (170, 60, 30)  # blue, BGR
    for i, (cx, cy) in enumerate(centres):
        inside = (xs - cx) ** 2 + (ys - cy) ** 2 <= radius**2
        images[i][inside] = (40, 240, 250)  # yellow
    return images, centres


def test_spatial_softmax_finds_the_peak_of_each_map():
    maps = torch.zeros(1, 2, 32, 32)
    maps[0, 0, 8, 24] = 50.0  # row 8, column 24
    maps[0, 1, 31, 0] = 50.0
    xy = spatial_softmax_xy(maps, torch.full((2,), 5.0))[0].numpy()
    lin = np.linspace(-1, 1, 32)
    np.testing.assert_allclose(xy, [lin[24], lin[8], lin[0], lin[31]], atol=1e-3)


def test_shapes_and_save_load_round_trip(tmp_path):
    torch.manual_seed(0)
    model = SpatialAutoencoder(SaeConfig(features=3))
    images, _ = disc_images(5)
    code = model.encode_bgr(images)
    assert code.shape == (5, 6) and code.dtype == np.float64
    assert np.all(np.abs(code) <= 1.0)
    assert model.reconstruct_bgr(images).shape == images.shape
    folder = model.save(tmp_path / "m")
    assert is_sae_folder(folder) and not is_sae_folder(tmp_path)
    again = load_sae(folder / "sae.pt")
    np.testing.assert_array_equal(again.encode_bgr(images), code)
    with pytest.raises(VaeError, match="ergo sae train"):
        load_sae(tmp_path / "nothing")


def test_training_lowers_the_loss_finds_the_disc_and_resumes_exactly(tmp_path):
    images, centres = disc_images(200)
    cfg = SaeConfig(features=2, channels=8, hidden=32)
    schedule = {"batch": 16, "seed": 1, "lr": 3e-3}
    model = train_sae(images, tmp_path / "a", cfg, TrainConfig(iterations=120, **schedule),
                      progress=False)  # fmt: skip
    # the reconstruction loss fell: what it can lose (above BCE(x, x), the images' own
    # entropy) more than halved since the first iteration
    start = train_sae(images, tmp_path / "start", cfg, TrainConfig(iterations=1, **schedule),
                      progress=False)  # fmt: skip
    x = torch.from_numpy(images[..., ::-1] / 255.0).permute(0, 3, 1, 2).float()
    floor = torch.nn.functional.binary_cross_entropy(x, x, reduction="sum") / len(x)
    with torch.no_grad():
        before, after = (float(m.loss(x)["loss"] - floor) for m in (start, model))
    assert after < 0.5 * before, (before, after)
    # one feature follows the disc: its x, y are near-linear in the disc's centre
    code = model.encode_bgr(images)
    a = np.hstack([code, np.ones((len(code), 1))])
    w, *_ = np.linalg.lstsq(a, centres, rcond=None)
    r2 = 1 - ((a @ w - centres) ** 2).sum(0) / ((centres - centres.mean(0)) ** 2).sum(0)
    assert r2.min() > 0.9, r2
    assert model.config.code_std is not None and len(model.config.code_std) == 4
    assert model.config.heldout_explained_variance > 0.3
    # resumed from a checkpoint half-way: the same model as the uninterrupted run
    train_sae(images, tmp_path / "b", cfg, TrainConfig(iterations=60, **schedule),
              progress=False)  # fmt: skip
    resumed = train_sae(images, tmp_path / "b", cfg, TrainConfig(iterations=120, **schedule),
                        progress=False)  # fmt: skip
    np.testing.assert_array_equal(resumed.encode_bgr(images), code)
    with pytest.raises(VaeError, match="same settings"):
        train_sae(images, tmp_path / "b", SaeConfig(features=3, channels=8, hidden=32),
                  TrainConfig(iterations=121, **schedule), progress=False)  # fmt: skip


def test_the_criterion_ranks_a_collapsed_model_below_a_trained_one():
    """Synthetic images: a model that redraws the disc where it is explains most of the
    held-out variance; one whose code carries nothing (it draws the mean image, or the disc
    always at one place) explains none or less than none. No label is used."""
    images, centres = disc_images(120, seed=3)
    train_idx, test_idx = heldout_split(len(images), 0.25, seed=0)
    mean_image = images[train_idx].astype(float).mean(axis=0)
    by_centre = {tuple(np.round(c, 6)): im for c, im in zip(centres, images, strict=True)}

    def trained(batch: np.ndarray) -> np.ndarray:  # knows where each disc is: redraws it
        return np.stack([by_centre[tuple(np.round(centres[i], 6))] for i in index_of(batch)])

    def index_of(batch: np.ndarray) -> list[int]:
        return [int(np.flatnonzero((images == im).all(axis=(1, 2, 3)))[0]) for im in batch]

    def collapsed(batch: np.ndarray) -> np.ndarray:
        return np.repeat(mean_image[None].round().astype(np.uint8), len(batch), axis=0)

    def stuck(batch: np.ndarray) -> np.ndarray:  # the disc always where the first one is
        return np.repeat(images[train_idx[0]][None], len(batch), axis=0)

    held = images[test_idx]
    good = explained_pixel_variance(trained, held, mean_image)
    none = explained_pixel_variance(collapsed, held, mean_image)
    worse = explained_pixel_variance(stuck, held, mean_image)
    assert good == pytest.approx(1.0)
    assert abs(none) < 0.01
    assert worse < none < good
    # and a real collapsed network: an untrained spatial autoencoder scores far below
    torch.manual_seed(0)
    untrained = SpatialAutoencoder(SaeConfig(features=2, channels=8, hidden=32))
    assert explained_pixel_variance(untrained.reconstruct_bgr, held, mean_image) < 0.5 * good


def test_heldout_split_is_a_seeded_partition():
    tr, te = heldout_split(50, 0.2, seed=4)
    assert len(te) == 10 and len(tr) == 40
    assert sorted(np.concatenate([tr, te]).tolist()) == list(range(50))
    tr2, te2 = heldout_split(50, 0.2, seed=4)
    assert np.array_equal(te, te2) and np.array_equal(tr, tr2)
    with pytest.raises(ValueError, match="held-out fraction"):
        heldout_split(10, 1.0, 0)


def test_distinct_features_keep_one_feature_per_moving_thing():
    """Label-free: from the code's statistics over the training images, features that do not
    move are dropped, and of features that follow the same thing (one predicts the other
    linearly) only the one that spreads most is kept."""
    from explore.learner.goal_spaces import spatial_goal_space
    from vision.spatial_code import distinct_features

    rng = np.random.default_rng(0)
    ball, other = rng.uniform(-0.5, 0.5, (500, 2)), rng.uniform(-0.5, 0.5, (500, 2))
    still = np.full((500, 2), 0.3) + rng.normal(0, 0.01, (500, 2))
    rotated = ball @ np.array([[0.6, -0.8], [0.8, 0.6]]) * 0.9 + 0.05  # the ball again
    drifting = 0.4 * ball + rng.normal(0, 0.1, (500, 2))  # spread 0.16: drifts, follows little
    code = np.hstack([still, rotated, other, ball, drifting])  # features 0..4
    std, corr = code.std(axis=0), np.corrcoef(code.T)
    assert distinct_features(std, corr) == [2, 3]  # the ball's widest copy and the other
    assert distinct_features(std) == [1, 2, 3]  # without correlations: every moving one
    space = spatial_goal_space(lambda im: code[: len(im)], std, modular=True, code_corr=corr)
    assert space.dim == 4 and [m.tolist() for m in space.modules] == [[0, 1], [2, 3]]
    np.testing.assert_array_equal(space.outcomes(np.zeros((3, 64, 64, 3)))[:, 2:], ball[:3])


def test_sae_train_command_says_which_features_move_in_words(tmp_path, capsys):
    """``ergo sae train`` names the features it keeps as a count of all of them, never as
    "features: 6 of 8" (which read as six kept when six was the index of the one kept)."""
    import re

    from explore.cli import main
    from vision.spatial_ae import load_sae
    from vision.spatial_code import distinct_features

    images, _ = disc_images(24)
    data = tmp_path / "d.npz"
    np.savez(data, images=images)
    out = tmp_path / "sae"
    assert main(["sae", "train", "--data", str(data), "--out", str(out), "--iterations", "2",
                 "--features", "3", "--no-progress"]) == 0  # fmt: skip
    printed = capsys.readouterr().out
    config = load_sae(out).config
    kept = distinct_features(config.code_std, config.code_corr)
    if kept:
        listed = ", ".join(map(str, kept))
        assert f"{len(kept)} of its 3 features move and follow distinct things" in printed
        assert re.search(rf"\(features? {listed}: one goal-space module each\)", printed), printed
    else:
        assert "none of its 3 features moves" in printed, printed
    assert "held-out explained pixel variance" in printed and printed.count("\n") == 1


def test_sae_train_on_a_few_images_says_none_was_held_out(tmp_path, capsys):
    """A dataset too small for a held-out image (a short run's outcomes) trains, and the
    command says the model was not judged, in words (no traceback)."""
    from explore.cli import main

    data = tmp_path / "few.npz"
    np.savez(data, images=disc_images(4)[0])
    out = tmp_path / "sae"
    assert main(["sae", "train", "--data", str(data), "--out", str(out), "--iterations", "2",
                 "--device", "cpu", "--no-progress"]) == 0  # fmt: skip
    assert "no image held out to judge it" in capsys.readouterr().out
    assert load_sae(out).config.heldout_explained_variance is None
