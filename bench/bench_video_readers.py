"""Which video decoders read an exported dataset's AV1 video, and how closely (docs/ecosystem.md).

Tries, in the interpreter that runs it, each decoder a LeRobot user may have, the way LeRobot
calls it (``lerobot/datasets/video_utils.py``: ``decode_video_frames_torchvision`` with its
"pyav" backend, ``decode_video_frames_torchcodec``), on ``DATASET``'s
``videos/observation.images.overhead/chunk-000/file-000.mp4``:

- PyAV (``av``): every frame in order, the reference;
- torchvision's ``io.VideoReader`` with the "pyav" backend (LeRobot's fallback): ``seek`` to an
  episode's first timestamp (key frames only, as LeRobot) and read on;
- torchcodec's ``VideoDecoder`` (LeRobot's default when installed): ``get_frames_played_at``
  the timestamps of every frame.

Per decoder: its version, whether it imports and decodes, the frames and the largest
difference from PyAV's (grey levels), frames a second. With ``--runs``, also the mean
difference of PyAV's frames from the frames the runs kept (what AV1 at crf 30 loses).

    python bench/bench_video_readers.py DATASET [--runs RUN ...]

Run it in each environment to compare (a throwaway venv per torchvision or torchcodec version;
docs/ecosystem.md lists those measured).
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Callable
from importlib import metadata
from pathlib import Path

import numpy as np

VIDEO = "videos/observation.images.overhead/chunk-000/file-000.mp4"


def version(dist: str) -> str:
    try:
        return metadata.version(dist)
    except metadata.PackageNotFoundError:
        return "not installed"


def episode_spans(dataset: Path) -> list[tuple[float, float]]:
    """(from_timestamp, to_timestamp) of every episode's frames in the video, s."""
    import pyarrow.parquet as pq

    rows = pq.read_table(dataset / "meta/episodes/chunk-000/file-000.parquet").to_pylist()
    key = "videos/observation.images.overhead"
    return [(r[f"{key}/from_timestamp"], r[f"{key}/to_timestamp"]) for r in rows]


def decode_pyav(path: Path, spans: list, fps: int) -> np.ndarray:
    """Every frame in order, (N, H, W, 3) RGB uint8."""
    import av

    with av.open(str(path)) as container:
        return np.stack([f.to_ndarray(format="rgb24") for f in container.decode(video=0)])


def decode_torchvision(path: Path, spans: list, fps: int) -> np.ndarray:
    """LeRobot's "pyav" backend: per episode, seek to its first frame and read its frames."""
    import torchvision

    torchvision.set_video_backend("pyav")
    reader = torchvision.io.VideoReader(str(path), "video")  # AttributeError where removed
    out = []
    for start, end in spans:
        reader.seek(start, keyframes_only=True)
        for frame in reader:
            ts = frame["pts"]
            if ts < start - 0.5 / fps:
                continue
            if ts >= end - 0.5 / fps:
                break
            out.append(frame["data"].permute(1, 2, 0).numpy())  # (C, H, W) -> (H, W, C)
    return np.stack(out)


def decode_torchcodec(path: Path, spans: list, fps: int) -> np.ndarray:
    """LeRobot's default: the frames played at every frame's timestamp."""
    from torchcodec.decoders import VideoDecoder

    decoder = VideoDecoder(str(path), device="cpu", seek_mode="approximate")
    times = [start + i / fps for start, end in spans for i in range(round((end - start) * fps))]
    batch = decoder.get_frames_played_at(seconds=times)
    return batch.data.permute(0, 2, 3, 1).numpy()


DECODERS: dict[str, tuple[str, Callable[[Path, list, int], np.ndarray]]] = {
    "PyAV (av)": ("av", decode_pyav),
    "torchvision io.VideoReader, pyav backend": ("torchvision", decode_torchvision),
    "torchcodec VideoDecoder": ("torchcodec", decode_torchcodec),
}


def kept_frames(runs: list[Path]) -> np.ndarray:
    """The frames the runs kept, in export order, (N, H, W, 3) RGB."""
    from explore.runs.store import read_frames, read_history

    out = []
    for run in runs:
        for rec in read_history(run).records:
            out.append(read_frames(run, rec.episode)[..., ::-1])  # BGR -> RGB
    return np.concatenate(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dataset", type=Path)
    ap.add_argument("--runs", type=Path, nargs="*", default=[], help="the exported runs")
    args = ap.parse_args()
    import torch  # noqa: F401 - the version printed below

    path = args.dataset / VIDEO
    fps = json.loads((args.dataset / "meta/info.json").read_text())["fps"]
    spans = episode_spans(args.dataset)
    print(f"{path}: {path.stat().st_size / 1e6:.2f} MB, {len(spans)} episodes at {fps} fps")
    print(f"torch {version('torch')}")
    reference = decode_pyav(path, spans, fps)
    if args.runs:
        kept = kept_frames(args.runs)
        diff = np.abs(reference.astype(int) - kept.astype(int))
        print(f"PyAV's frames against the kept ones: mean {diff.mean():.2f}, max {diff.max()}")
    for name, (dist, decode) in DECODERS.items():
        label = f"{name} {version(dist)}"
        t0 = time.perf_counter()
        try:
            frames = decode(path, spans, fps)
        except Exception as exc:  # what the reader says is the measurement
            line = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
            print(f"{label}: FAILS, {type(exc).__name__}: {line[:160]}")
            continue
        dt = time.perf_counter() - t0
        same = frames.shape == reference.shape
        worst = int(np.abs(frames.astype(int) - reference.astype(int)).max()) if same else -1
        print(
            f"{label}: {len(frames)} frames {frames.shape[1:]} in {dt:.2f} s "
            f"({len(frames) / dt:.0f} frames/s); "
            + (f"largest difference from PyAV's {worst}" if same else "not PyAV's frame count")
        )


if __name__ == "__main__":
    main()
