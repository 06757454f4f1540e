"""``ergo find-cameras`` (device indices that open, with their resolution), ``ergo track``
(the ball tracker on any camera source, one line per frame) and ``ergo vae train`` (the learned
goal space's representation, on a dataset of outcome images).

Imports nothing heavy at module level: OpenCV and torch are imported inside the commands.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

MAX_INDEX = 10  # device indices probed by default (/dev/video0..9): a convention


def register(sub: argparse._SubParsersAction) -> None:
    find = sub.add_parser("find-cameras", help="list camera device indices that open")
    find.add_argument("--max-index", type=int, default=MAX_INDEX, help="probe 0..N-1")
    find.set_defaults(func=_find_cameras)

    track = sub.add_parser("track", help="track the ball, one line per frame")
    track.add_argument(
        "--camera",
        required=True,
        help="device index, video file, folder of images, or stream URL (127.0.0.1 only)",
    )
    track.add_argument("--frames", type=int, default=None, help="stop after N frames")
    track.add_argument(
        "--arena",
        type=Path,
        default=None,
        help="arena calibration file (from `ergo calibrate arena`): positions in metres",
    )
    track.add_argument(
        "--hsv",
        action="append",
        default=None,
        metavar="H,S,V:H,S,V",
        help="ball colour range lower:upper (repeat for red); default: the arena file's or the "
        "original rig's",
    )
    track.add_argument("--width", type=int, default=None, help="requested width, px")
    track.add_argument("--height", type=int, default=None, help="requested height, px")
    track.add_argument("--fps", type=float, default=None, help="requested frame rate")
    track.add_argument("--fourcc", default=None, help="requested pixel format, e.g. MJPG")
    track.set_defaults(func=_track)

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
    t.add_argument("--batch", type=int, default=None, help="batch size (default 64)")
    t.add_argument("--seed", type=int, default=0, help="random seed")
    t.add_argument(
        "--device", choices=("auto", "cpu", "cuda"), default="auto",
        help="where to train: a CUDA GPU where torch sees one (auto, the default), or cpu/cuda",
    )  # fmt: skip
    t.add_argument("--no-progress", action="store_true", help="no progress bar")
    t.set_defaults(func=_vae_train)


def _error(message: str) -> int:
    print(f"ergo: error: {message}", file=sys.stderr)
    return 2


def parse_hsv(text: str):
    """``"27,45,70:38,255,255"`` -> ``HSVRange``."""
    from vision.tracker import HSVRange

    try:
        lo, hi = text.split(":")
        return HSVRange(tuple(int(v) for v in lo.split(",")), tuple(int(v) for v in hi.split(",")))
    except ValueError as exc:
        raise ValueError(f"bad --hsv {text!r} ({exc}): expected H,S,V:H,S,V") from None


def load_arena_file(path: Path):
    """(ArenaModel, list of HSVRange or None, ball radius m or None) from an arena file.

    The file's format belongs to ``calibration.store`` (which validates it when writing);
    only its ``data`` object is read here, since ``vision`` imports no other package.
    """
    from vision.rectify import ArenaModel
    from vision.tracker import HSVRange

    try:
        data = json.loads(path.read_text())["data"]
        model = ArenaModel.from_dict(data)
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise ValueError(f"cannot read arena calibration {path}: {exc}") from None
    ranges = data.get("ball_hsv_ranges")
    ranges = [HSVRange.from_list(r) for r in ranges] if ranges else None
    return model, ranges, data.get("ball_radius_m")


def _find_cameras(args: argparse.Namespace) -> int:
    import cv2

    cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_ERROR)
    found = 0
    for index in range(args.max_index):
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


def _track(args: argparse.Namespace) -> int:
    import dataclasses

    from vision.camera import CameraError, make_camera
    from vision.tracker import BallTracker, TrackerConfig

    arena, ranges, ball_radius = None, None, None
    try:
        if args.arena is not None:
            arena, ranges, ball_radius = load_arena_file(args.arena)
        if args.hsv:
            ranges = [parse_hsv(h) for h in args.hsv]
    except ValueError as exc:
        return _error(str(exc))
    config = TrackerConfig()
    if ranges:
        config = dataclasses.replace(config, ranges=tuple(ranges))
    if ball_radius:
        config = dataclasses.replace(config, ball_radius_m=float(ball_radius))
    tracker = BallTracker(config, arena)
    try:
        camera = make_camera(args.camera, args.width, args.height, args.fps, args.fourcc)
    except CameraError as exc:
        return _error(str(exc))
    n = 0
    try:
        with camera:
            for warning in getattr(camera, "settings_warnings", []):
                print(f"warning: camera ignored a setting: {warning}", file=sys.stderr)
            while args.frames is None or n < args.frames:
                try:
                    frame = camera.read()
                except CameraError as exc:
                    if n and "end of replay" in str(exc):
                        break
                    raise
                obs = tracker.track(frame.image)
                print(f"frame {n} t={frame.timestamp:.3f}s: {obs.describe()}", flush=True)
                n += 1
    except CameraError as exc:
        return _error(str(exc))
    except KeyboardInterrupt:
        pass
    return 0


def _vae_train(args: argparse.Namespace) -> int:
    from vision.vae import VaeConfig, VaeError
    from vision.vae_train import TrainConfig, load_images, resolve_device, train_vae

    try:
        images = load_images(args.data)
        model_cfg = VaeConfig(
            beta=1.0 if args.beta is None else args.beta,
            capacity=args.capacity,
            capacity_iterations=args.capacity_iterations or VaeConfig().capacity_iterations,
        )
        defaults = TrainConfig()
        train_cfg = TrainConfig(
            iterations=args.iterations or defaults.iterations,
            lr=args.lr or defaults.lr,
            batch=args.batch or defaults.batch,
            seed=args.seed,
            device=args.device,
        )
        vae = train_vae(images, args.out, model_cfg, train_cfg, progress=not args.no_progress)
    except VaeError as exc:
        return _error(str(exc))
    kl = ", ".join(f"{v:.2f}" for v in vae.config.kl_per_latent or [])
    print(f"{args.out}: VAE saved (trained on {resolve_device(args.device)}); "
          f"KL per latent (nats): {kl}")  # fmt: skip
    return 0
