"""The VAE's two training aids: the decoder's mean-image offset and the delayed, warmed-up KL
term (vision/vae.py; docs/results.md F6)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from vision.vae import Vae, VaeConfig, VaeError, load_vae, to_tensor
from vision.vae_train import TrainConfig, train_vae

torch.set_num_threads(1)


def square_images(n: int = 24, seed: int = 0) -> np.ndarray:
    """Grey images (n, 64, 64, 3) BGR with one bright square at a random place."""
    rng = np.random.default_rng(seed)
    images = np.full((n, 64, 64, 3), 60, dtype=np.uint8)
    images[:, :8] = 255  # a white band in every image: its mean is 1, its logit clipped
    for img, (x, y) in zip(images, rng.integers(10, 48, (n, 2)), strict=True):
        img[y : y + 10, x : x + 10] = (0, 200, 255)
    return images


def test_an_untrained_decoder_with_the_offset_draws_the_mean_image():
    images = square_images()
    torch.manual_seed(0)
    vae = Vae(VaeConfig(mean_image_offset=True))
    vae.set_mean_image(images)
    with torch.no_grad():
        vae.decoder_conv[-1].weight.zero_()  # the decoder's own logits: its last bias only
        vae.decoder_conv[-1].bias.zero_()
    drawn = vae.decode_bgr(vae.encode_bgr(images[:2])).astype(float)
    mean = images.astype(float).mean(axis=0)
    assert np.abs(drawn - mean).max() <= 1.0  # rounding to uint8
    assert np.isfinite(vae.pixel_offset.numpy()).all()  # the white band's mean is 1: clipped


def test_the_offset_is_the_training_images_mean_and_survives_save_and_load(tmp_path):
    images = square_images()
    cfg = TrainConfig(iterations=3, batch=4, threads=1, checkpoint_every=3)
    vae = train_vae(images, tmp_path / "m", VaeConfig(mean_image_offset=True), cfg,
                    progress=False)  # fmt: skip
    p = to_tensor(images).mean(dim=0).clamp(1e-3, 1 - 1e-3)
    assert torch.allclose(vae.pixel_offset, torch.log(p / (1 - p)), atol=1e-4)
    back = load_vae(tmp_path / "m")
    assert back.config.mean_image_offset and torch.equal(back.pixel_offset, vae.pixel_offset)
    assert np.array_equal(back.decode_bgr(np.zeros((1, 10))), vae.decode_bgr(np.zeros((1, 10))))


def test_a_model_without_the_offset_has_no_buffer_and_refuses_to_set_one():
    vae = Vae(VaeConfig())
    assert "pixel_offset" not in vae.state_dict()
    with pytest.raises(VaeError, match="mean_image_offset is off"):
        vae.set_mean_image(square_images(2))


def test_the_kl_weight_is_zero_during_the_delay_then_rises_linearly_to_one():
    cfg = VaeConfig(kl_delay=100, kl_warmup=50)
    assert [cfg.kl_weight(i) for i in (0, 99, 100, 125, 150, 10_000)] == [0, 0, 0, 0.5, 1, 1]
    assert VaeConfig(kl_delay=10).kl_weight(9) == 0 and VaeConfig(kl_delay=10).kl_weight(10) == 1
    assert VaeConfig().kl_weight(0) == 1
    with pytest.raises(VaeError, match="kl_delay"):
        VaeConfig(kl_delay=-1).validate()


@pytest.mark.parametrize("capacity", [None, 5.0])
def test_the_loss_weighs_the_kl_term_by_the_schedule(capacity):
    vae = Vae(VaeConfig(beta=4.0, capacity=capacity, capacity_iterations=10, kl_delay=20,
                        kl_warmup=20))  # fmt: skip
    x = to_tensor(square_images(4))
    terms = {}
    for it in (0, 30, 60):
        torch.manual_seed(1)
        with torch.no_grad():
            terms[it] = {k: float(v) for k, v in vae.loss(x, iteration=it).items()}
    kl_part = terms[60]["kl"] if capacity is None else abs(terms[60]["kl"] - capacity)
    assert terms[0]["loss"] == pytest.approx(terms[0]["recon"], rel=1e-6)  # delayed: no KL
    assert terms[30]["loss"] == pytest.approx(terms[30]["recon"] + 0.5 * 4 * kl_part, rel=1e-6)
    assert terms[60]["loss"] == pytest.approx(terms[60]["recon"] + 4 * kl_part, rel=1e-6)


def test_a_resumed_training_with_both_aids_equals_the_uninterrupted_one(tmp_path):
    images = square_images()
    model = VaeConfig(beta=10.0, capacity=5.0, capacity_iterations=4, mean_image_offset=True,
                      kl_delay=4, kl_warmup=4)  # fmt: skip

    def cfg(iterations: int) -> TrainConfig:
        return TrainConfig(iterations=iterations, batch=8, threads=1, checkpoint_every=5)

    straight = train_vae(images, tmp_path / "a", model, cfg(10), progress=False)
    train_vae(images, tmp_path / "b", model, cfg(5), progress=False)
    resumed = train_vae(images, tmp_path / "b", model, cfg(10), progress=False)
    for k, v in straight.state_dict().items():
        assert torch.equal(v, resumed.state_dict()[k]), k


def test_the_train_command_takes_the_aids(tmp_path):
    from explore.cli import main

    data = tmp_path / "d.npz"
    np.savez(data, images=square_images(8))
    out = tmp_path / "m"
    assert main(["vae", "train", "--data", str(data), "--out", str(out), "--iterations", "2",
                 "--batch", "4", "--mean-image-offset", "--kl-delay", "1000", "--kl-warmup",
                 "500", "--no-progress"]) == 0  # fmt: skip
    cfg = load_vae(out).config
    assert (cfg.mean_image_offset, cfg.kl_delay, cfg.kl_warmup) == (True, 1000, 500)
    assert main(["vae", "train", "--data", str(data), "--out", str(tmp_path / "bad"),
                 "--kl-warmup", "-1", "--no-progress"]) == 2  # fmt: skip
