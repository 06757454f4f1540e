"""Damaged model and dataset files get one line, never a traceback (issue 29): a VAE's or a
spatial autoencoder's ``.pt``/``.json`` or a training ``checkpoint.pt`` truncated, garbage or
empty; a model ``.json`` whose statistics are NaN or of the wrong length; a dataset ``.npz``
empty, truncated or actually an ``.npy``. Each through the command a user runs (``ergo vae
train``, ``ergo sae train``) or the strategy that loads the model (``ergo explore``'s)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch

from explore.cli import main
from explore.learner.strategies import StrategyError, make_strategy
from explore.rigs.arena import TWIN_ARENA
from vision.sae_train import train_sae
from vision.spatial_ae import SaeConfig
from vision.vae import VaeConfig
from vision.vae_train import TrainConfig, train_vae

torch.set_num_threads(1)
TRAIN = ["--iterations", "2", "--batch", "4", "--no-progress"]


def _images(n: int = 8) -> np.ndarray:
    rng = np.random.default_rng(0)
    return rng.integers(0, 255, (n, 64, 64, 3), dtype=np.uint8)


@pytest.fixture(scope="module")
def models(tmp_path_factory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("models")
    cfg = TrainConfig(iterations=2, batch=4, seed=0)
    train_vae(_images(), root / "vae", VaeConfig(channels=4, hidden=8), cfg, progress=False)
    train_sae(
        _images(), root / "sae", SaeConfig(features=2, channels=4, hidden=8), cfg, progress=False
    )
    np.savez(root / "data.npz", images=_images())
    return {"vae": root / "vae", "sae": root / "sae", "data": root / "data.npz"}


def _damage(path: Path, how: str) -> None:
    data = path.read_bytes()
    path.write_bytes({"truncated": data[: len(data) // 2], "garbage": b"\x80\x04garbage\xff" * 7,
                      "empty": b""}[how])  # fmt: skip


def _strategy(kind: str, folder: Path) -> None:
    name, option = ("rge-vae", "vae") if kind == "vae" else ("rge-sae", "sae")
    make_strategy(name, n_params=48, scene=TWIN_ARENA, **{option: str(folder)})


def _one_line(exc: BaseException) -> str:
    text = str(exc)
    assert "\n" not in text, text
    return text


@pytest.mark.parametrize("how", ["truncated", "garbage", "empty"])
@pytest.mark.parametrize("file", ["vae.pt", "vae.json", "sae.pt", "sae.json"])
def test_a_damaged_model_file_is_one_line(models, tmp_path, file, how):
    kind = file.split(".")[0]
    folder = tmp_path / kind
    shutil.copytree(models[kind], folder)
    _damage(folder / file, how)
    with pytest.raises(StrategyError) as info:
        _strategy(kind, folder)
    assert file in _one_line(info.value)


@pytest.mark.parametrize("how", ["truncated", "garbage", "empty"])
@pytest.mark.parametrize("kind", ["vae", "sae"])
def test_a_damaged_training_checkpoint_is_one_line(models, tmp_path, kind, how, capsys):
    folder = tmp_path / kind
    shutil.copytree(models[kind], folder)
    _damage(folder / "checkpoint.pt", how)
    train = TRAIN if kind == "vae" else ["--iterations", "2", "--no-progress"]
    args = [kind, "train", "--data", str(models["data"]), "--out", str(folder), *train]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "checkpoint.pt" in err and err.count("\n") == 1, err


@pytest.mark.parametrize(
    ("kind", "field", "value"),
    [("vae", "latent_std", [float("nan")] * 10), ("vae", "latent_mean", [0.0, 1.0]),
     ("vae", "kl_per_latent", "abc"), ("sae", "code_std", [float("nan")] * 4),
     ("sae", "code_mean", [0.0]), ("sae", "code_corr", [[1.0]])],
)  # fmt: skip
def test_a_model_json_with_bad_statistics_is_refused(models, tmp_path, kind, field, value):
    folder = tmp_path / kind
    shutil.copytree(models[kind], folder)
    path = folder / f"{kind}.json"
    config = json.loads(path.read_text())
    config[field] = value
    if kind == "vae":
        config["latent_dim"] = 10
    path.write_text(json.dumps(config))  # json writes NaN as NaN
    with pytest.raises(StrategyError) as info:
        _strategy(kind, folder)
    assert field in _one_line(info.value)


@pytest.mark.parametrize("how", ["empty", "truncated", "npy"])
def test_a_damaged_dataset_is_one_line(models, tmp_path, how, capsys):
    data = tmp_path / "data.npz"
    if how == "npy":
        with open(data, "wb") as f:
            np.save(f, _images())  # an .npy saved under the .npz name
    else:
        shutil.copy(models["data"], data)
        _damage(data, "empty" if how == "empty" else "truncated")
    assert main(["vae", "train", "--data", str(data), "--out", str(tmp_path / "m"), *TRAIN]) == 2
    err = capsys.readouterr().err
    assert str(data) in err and err.count("\n") == 1, err
