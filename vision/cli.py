"""``ergo find-cameras`` (device indices that open, with their resolution) and ``ergo vae
train`` (the learned goal space's representation, on a dataset of outcome images). ``ergo
track`` is in ``calibration.cli``: it reads the arena calibration file.

Imports nothing heavy at module level: OpenCV and torch are imported inside the commands.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from plumbing.cli_errors import error

MAX_INDEX = 10  # device indices probed by default (/dev/video0..9): a convention


def register(sub: argparse._SubParsersAction) -> None:
    find = sub.add_parser("find-cameras", help="list camera device indices that open")
    find.add_argument("--max-index", type=int, default=MAX_INDEX, help="probe 0..N-1")
    find.set_defaults(func=_find_cameras)

    v = sub.add_parser("vae", help="representation learning (VAE)")
    vsub = v.add_subparsers(dest="vae_command", metavar="COMMAND")
    vsub.required = True
    t = vsub.add_parser(
        "train", help="train a VAE on an outcome database", description="Resumable: rerun the "
        "same command to continue from the last checkpoint in --out.",
    )  # fmt: skip
    t.add_argument("--data", type=Path, required=True, help="dataset .npz (ergo dataset outcomes)")
    t.add_argument("--out", type=Path, required=True, help="model folder")
    t.add_argument("--iterations", type=int, default=None, help="total iterations (default 3000)")
    t.add_argument("--beta", type=float, default=None, help="KL weight (default 1: plain VAE)")
    t.add_argument("--capacity", type=float, default=None, help="final KL capacity C, nats")
    t.add_argument(
        "--capacity-iterations", type=int, default=None, metavar="N",
        help="iterations over which C rises from 0 (default 2000; docs/results.md: 500)",
    )  # fmt: skip
    t.add_argument("--lr", type=float, default=None, help="Adam learning rate (default 1e-3)")
    t.add_argument(
        "--lr-final", type=float, default=None, metavar="LR",
        help="decay the rate from --lr to LR along a half cosine over the run (default: none)",
    )  # fmt: skip
    t.add_argument("--batch", type=int, default=None, help="batch size (default 64)")
    t.add_argument(
        "--channels-last", action="store_true",
        help="channels-last memory layout (about 8%% less CPU an iteration here; docs/results.md)",
    )  # fmt: skip
    t.add_argument(
        "--mean-image-offset", action="store_true",
        help="the decoder adds the mean training image's logit to its own (docs/results.md F6)",
    )  # fmt: skip
    t.add_argument(
        "--kl-delay", type=int, default=0, metavar="N",
        help="train N iterations without the KL term first (default 0)",
    )  # fmt: skip
    t.add_argument(
        "--kl-warmup", type=int, default=0, metavar="N",
        help="then raise the KL weight linearly from 0 to 1 over N iterations (default 0)",
    )  # fmt: skip
    _add_training_arguments(t)
    t.set_defaults(func=_vae_train)

    a = sub.add_parser("sae", help="representation learning (spatial autoencoder)")
    asub = a.add_subparsers(dest="sae_command", metavar="COMMAND")
    asub.required = True
    t = asub.add_parser(
        "train", help="train a spatial autoencoder on an outcome database",
        description="Resumable: rerun the same command to continue from the last checkpoint.",
    )  # fmt: skip
    t.add_argument("--data", type=Path, required=True, help="dataset .npz (ergo dataset outcomes)")
    t.add_argument("--out", type=Path, required=True, help="model folder")
    t.add_argument("--iterations", type=int, default=None, help="total iterations (default 700)")
    t.add_argument("--features", type=int, default=8, help="feature maps (default 8)")
    _add_training_arguments(t)
    t.set_defaults(func=_sae_train)


def _add_training_arguments(t: argparse.ArgumentParser) -> None:
    """Seeds, device and progress of a representation's training."""
    t.add_argument("--seed", type=int, default=0, help="random seed")
    t.add_argument(
        "--seeds", default=None, metavar="SEEDS",
        help="train several seeds (8, 0-7 or 0,3) into OUT/seed-S and keep in OUT the one that "
        "best explains held-out images (selection.json)",
    )  # fmt: skip
    t.add_argument(
        "--device", choices=("auto", "cpu", "cuda"), default="auto",
        help="where to train: a CUDA GPU where torch sees one (auto, the default), or cpu/cuda",
    )  # fmt: skip
    t.add_argument("--no-progress", action="store_true", help="no progress bar")


def parse_seeds(text: str) -> list[int]:
    """The seeds syntax of every command that takes ``--seeds`` (``ergo vae train``, ``ergo sae
    train``, ``ergo experiment``): "8" -> [0..7] (a count), "0,2,5" -> [0, 2, 5], "3-7" ->
    [3..7], "4-4" -> [4]; lists may mix both ("0,3-5"). Raises ``ValueError`` (one line)."""
    text = text.strip()
    if "," not in text and "-" not in text:
        try:
            count = int(text)
        except ValueError:
            raise ValueError(f"--seeds {text!r}: give a count, a list or a range") from None
        if count < 1:
            raise ValueError(f"--seeds {count}: a count must be at least 1 (one seed S: S-S)")
        return list(range(count))
    items = [s.strip() for s in text.split(",") if s.strip()]
    if not items:
        raise ValueError("--seeds: give at least one value")
    seeds: list[int] = []
    for item in items:
        try:
            bounds = [int(v) for v in item.split("-")] if "-" in item else [int(item)] * 2
        except ValueError:  # also a negative seed: "-1" splits into "" and "1"
            raise ValueError(f"--seeds {item!r}: not a seed or a range of seeds") from None
        if len(bounds) != 2:
            raise ValueError(f"--seeds {item!r}: not a seed or a range of seeds")
        lo, hi = bounds
        if hi < lo:
            raise ValueError(f"--seeds {item}: an empty range")
        seeds.extend(range(lo, hi + 1))
    return list(dict.fromkeys(seeds))  # each seed once, in the order given


def _seeds_of(args: argparse.Namespace) -> list[int]:
    """The training seeds: ``--seeds`` if given, else ``--seed``."""
    return parse_seeds(args.seeds) if args.seeds is not None else [args.seed]


def _find_cameras(args: argparse.Namespace) -> int:
    import cv2

    from vision.opencv_camera import opencv_errors_only

    found = 0
    for index in range(args.max_index):
        with opencv_errors_only():
            cap = cv2.VideoCapture(index, cv2.CAP_V4L2)
            if not cap.isOpened():
                cap = cv2.VideoCapture(index)
        if not cap.isOpened():
            continue
        ok, image = cap.read()
        fps = cap.get(cv2.CAP_PROP_FPS)
        backend = cap.getBackendName()
        cap.release()
        if ok and image is not None:
            h, w = image.shape[:2]
            print(f"{index}: {w}x{h} at {fps:g} fps ({backend})")
        else:
            print(f"{index}: opens but delivers no frame ({backend})")
        found += 1
    if not found:
        print(f"no camera among device indices 0..{args.max_index - 1}")
    return 0


def _vae_train(args: argparse.Namespace) -> int:
    from vision.representation_quality import HELDOUT, train_and_select
    from vision.vae import VaeConfig, VaeError
    from vision.vae_train import TrainConfig, load_images, resolve_device, train_vae

    try:
        seeds = _seeds_of(args)
        images = load_images(args.data)
        model_cfg = VaeConfig(
            beta=1.0 if args.beta is None else args.beta,
            capacity=args.capacity,
            capacity_iterations=args.capacity_iterations or VaeConfig().capacity_iterations,
            mean_image_offset=args.mean_image_offset,
            kl_delay=args.kl_delay,
            kl_warmup=args.kl_warmup,
        )
        model_cfg.validate()
        defaults = TrainConfig()

        def train_one(seed: int, out: Path) -> Any:
            cfg = TrainConfig(
                iterations=args.iterations or defaults.iterations, lr=args.lr or defaults.lr,
                lr_final=args.lr_final, batch=args.batch or defaults.batch, seed=seed,
                device=args.device, channels_last=args.channels_last,
            )  # fmt: skip
            return train_vae(
                images, out, model_cfg, cfg, progress=not args.no_progress, heldout=HELDOUT
            )

        vae = train_and_select(args.out, seeds, train_one)
    except (VaeError, ValueError) as exc:
        return error(exc)
    kl = ", ".join(f"{v:.2f}" for v in vae.config.kl_per_latent or [])
    print(f"{args.out}: VAE saved (trained on {resolve_device(args.device)}); "
          f"KL per latent (nats): {kl}; "
          f"{_explained(vae.config.heldout_explained_variance)}")  # fmt: skip
    return 0


def _explained(value: float | None) -> str:
    """The held-out explained pixel variance in words (vision.representation_quality); None:
    none was measured (a dataset too small for a held-out image)."""
    if value is None:
        return "no image held out to judge it (too few images in the dataset)"
    what = f"held-out explained pixel variance {value:.3f}"
    if value < 0:
        return (
            f"{what}: WORSE than the mean training image (0 = the mean image, 1 = perfect); "
            "this model's code carries nothing usable: train longer or on more images"
        )
    return f"{what} (0 = no better than the mean training image, 1 = perfect)"


def _sae_train(args: argparse.Namespace) -> int:
    from vision.representation_quality import HELDOUT, train_and_select
    from vision.sae_train import SAE_ITERATIONS, train_sae
    from vision.spatial_ae import SaeConfig
    from vision.spatial_code import distinct_features
    from vision.vae import VaeError
    from vision.vae_train import TrainConfig, load_images

    try:
        seeds = _seeds_of(args)
        images = load_images(args.data)
        model_cfg = SaeConfig(features=args.features)
        model_cfg.validate()

        def train_one(seed: int, out: Path) -> Any:
            cfg = TrainConfig(
                iterations=args.iterations or SAE_ITERATIONS, seed=seed, device=args.device
            )
            return train_sae(images, out, model_cfg, cfg, HELDOUT, progress=not args.no_progress)

        sae = train_and_select(args.out, seeds, train_one)
    except (VaeError, ValueError) as exc:
        return error(exc)
    kept = distinct_features(sae.config.code_std, sae.config.code_corr)
    n = sae.config.features
    features = (
        f"{len(kept)} of its {n} features move and follow distinct things "
        f"(feature{'s' * (len(kept) > 1)} {', '.join(map(str, kept))}: one goal-space module "
        "each)"
        if kept
        else f"none of its {n} features moves: a goal space of it would have no module"
    )
    print(f"{args.out}: spatial autoencoder saved; {features}; "
          f"{_explained(sae.config.heldout_explained_variance)}")  # fmt: skip
    return 0
