"""``ergo export lerobot``: run folders as one LeRobotDataset v3.0, written with pyarrow and PyAV.

The layout and its fields are LeRobot's (huggingface/lerobot, ``lerobot/datasets/utils.py``,
``dataset_metadata.py``, ``dataset_writer.py``, ``compute_stats.py``, read 2026-12-01; its v3.0
blog post), written here because lerobot itself cannot be installed beside this project (its
releases pin torch, rerun-sdk and OpenCV below the versions used here)::

    OUT/meta/info.json                       codebase_version "v3.0", fps, features, templates
    OUT/meta/stats.json                      per feature: min max mean std count q01 ... q99
    OUT/meta/tasks.parquet                   task (the index) -> task_index
    OUT/meta/episodes/chunk-000/file-000.parquet   one row per episode: where its frames are
    OUT/data/chunk-000/file-000.parquet      one row per frame, every episode
    OUT/videos/observation.images.overhead/chunk-000/file-000.mp4   (runs with record_video)

One exploration episode is one dataset episode: its movement, one frame per control tick (40 Hz),
``observation.state`` the joints read and ``action`` the command sent at that tick
(``explore.export.episodes``), the automatic columns (``timestamp``, ``frame_index``,
``episode_index``, ``index``, ``task_index``), and per-episode features repeated on each of its
frames: ``episode.dmp_parameters`` (the 48 motor parameters), ``episode.goal``,
``episode.context`` and ``episode.outcome`` in the run's goal space (NaN where there is none).
The ``task`` is what the strategy was doing ("motor babbling", "goal in module k"). Each episode
row also names where it comes from (``ergo/run``, ``ergo/episode``, ``ergo/strategy``,
``ergo/seed``; ``ergo/run`` is the run's name, never a path of the exporting machine: see
``run_names``). Every file goes into a temporary folder beside ``OUT`` (``.OUT.partial-PID``:
one per export, so that two exports to one ``OUT`` never remove each other's), renamed to
``OUT`` at the end: an export that fails leaves nothing, and of two exports to one ``OUT`` the
second to finish says so and leaves the first's dataset alone.
"""

from __future__ import annotations

import errno
import glob
import json
import os
import shutil
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from explore.export.episodes import (
    ExportEpisode,
    ExportError,
    RunSource,
    has_frames,
    iter_episodes,
    open_source,
)
from robot.spec import ERGO_JR_JOINTS

CODEBASE_VERSION = "v3.0"
ROBOT_TYPE = "poppy_ergo_jr"
# LeRobot's defaults (lerobot/datasets/utils.py): files per chunk folder, MB per file. This
# writer puts every episode in file-000 of chunk-000 (a 5000-episode twin run is some 60 MB of
# frames and a few MB of video at 128 px).
CHUNKS_SIZE = 1000
DATA_FILES_SIZE_IN_MB = 100
VIDEO_FILES_SIZE_IN_MB = 200
DATA_PATH = "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
VIDEO_PATH = "videos/{video_key}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4"
EPISODES_PATH = "meta/episodes/chunk-000/file-000.parquet"
VIDEO_KEY = "observation.images.overhead"
QUANTILES = (0.01, 0.10, 0.50, 0.90, 0.99)  # LeRobot's DEFAULT_QUANTILES (compute_stats.py)
AUTO_FEATURES = ("timestamp", "frame_index", "episode_index", "index", "task_index")
# The names of ``observation.state`` and ``action``: each joint's position, ``m1.pos`` ..
# ``m6.pos``, LeRobot's convention for an arm's joints (its lerobot-rollout hands a policy only
# the features named ``*.pos``); the Ergo Jr's LeRobot robots (lerobot_plugins/) take them.
JOINT_FEATURES = tuple(f"{j}.pos" for j in ERGO_JR_JOINTS)


@dataclass
class ExportSummary:
    """What an export wrote.

    Attributes:
        out: the dataset folder. episodes, frames, tasks: how many. video_side: frame side,
        pixels (0 without video). warnings: one line each (a torn record left out, ...).
    """

    out: Path
    episodes: int
    frames: int
    tasks: list[str]
    video_side: int
    warnings: list[str] = field(default_factory=list)


def _vector(names: list[str]) -> dict[str, Any]:
    return {"dtype": "float32", "shape": [len(names)], "names": names}


def features(
    n_joints: int, n_params: int, goal_dim: int, context_dim: int, video_side: int
) -> dict[str, dict[str, Any]]:
    """The dataset's ``features`` (``info.json``): dtype, shape and names of every column."""
    joints = list(JOINT_FEATURES)[:n_joints]
    out: dict[str, dict[str, Any]] = {
        "observation.state": _vector(joints),
        "action": _vector(joints),
        "episode.dmp_parameters": _vector([f"p{i}" for i in range(n_params)]),
        "episode.goal": _vector([f"g{i}" for i in range(goal_dim)]),
        "episode.context": _vector([f"c{i}" for i in range(context_dim)]),
        "episode.outcome": _vector([f"g{i}" for i in range(goal_dim)]),
    }
    if video_side:
        from explore.export.video import encoder_info

        out[VIDEO_KEY] = {
            "dtype": "video",
            "shape": [video_side, video_side, 3],
            "names": ["height", "width", "channels"],
            "info": {"video.height": video_side, "video.width": video_side, **encoder_info()},
        }
    out["timestamp"] = {"dtype": "float32", "shape": [1], "names": None}
    for key in AUTO_FEATURES[1:]:
        out[key] = {"dtype": "int64", "shape": [1], "names": None}
    return out


def _check_compatible(sources: list[RunSource]) -> tuple[int, int]:
    """The shared control rate (Hz, an integer: LeRobot's fps) and motor parameter count."""
    first = sources[0]
    rate = first.config.episode.rate_hz
    n_params = len(first.records[0].theta)
    for s in sources[1:]:
        if s.config.episode.rate_hz != rate:
            raise ExportError(
                f"{s.path} runs at {s.config.episode.rate_hz} Hz and {first.path} at {rate} Hz: "
                "a dataset has one frame rate; export them apart"
            )
        if len(s.records[0].theta) != n_params:
            raise ExportError(
                f"{s.path} plays {len(s.records[0].theta)} motor parameters and {first.path} "
                f"{n_params}: export them apart"
            )
    if rate != round(rate):
        raise ExportError(f"{first.path} runs at {rate} Hz: LeRobot datasets need an integer fps")
    return round(rate), n_params


def _video_choice(sources: list[RunSource], video: bool) -> bool:
    if not video:
        return False
    kept = [has_frames(s) for s in sources]
    if all(kept):
        return True
    if any(kept):
        missing = next(s.path for s, k in zip(sources, kept, strict=True) if not k)
        raise ExportError(
            f"{missing} has no camera frames (it ran without --rig-option record_video=SIDE) "
            "while other runs have: export them apart, or all with --no-video"
        )
    return False


def _remove_dead_partials(out: Path) -> None:
    """Remove what earlier exports to ``out`` left when they died (``.OUT.partial-PID`` of a
    process that is gone); a running export's folder is its own, never touched."""
    for tmp in out.parent.glob(f".{glob.escape(out.name)}.partial*"):
        pid = tmp.name.rsplit("-", 1)[-1]
        if pid.isdigit() and _alive(int(pid)):
            continue
        shutil.rmtree(tmp, ignore_errors=True)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def run_names(paths: list[Path]) -> list[str]:
    """What the dataset calls each run (``ergo/run``): its folder relative to the folder that
    holds every exported run, e.g. ``"A"`` for ``runs/A`` alone, ``"rge-efr/seed-0"`` for trials
    of a campaign. Never an absolute path: the user's file system would be published with a
    dataset pushed to the Hub."""
    resolved = [Path(p).resolve() for p in paths]
    common = Path(os.path.commonpath([p.parent for p in resolved]))
    return [p.relative_to(common).as_posix() for p in resolved]


def check_out(out: Path) -> None:
    """``--out`` must be new or an empty folder (an ``ExportError`` otherwise)."""
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise ExportError(f"{out} exists and is not empty: give a new --out (nothing was written)")


def export_lerobot(runs: list[Path], out: Path, video: bool = True) -> ExportSummary:
    """Write the runs' episodes, in order, as one LeRobotDataset v3.0 in ``out``.

    Args:
        runs: run folders (their episodes in the order given).
        out: the dataset folder: new, or an empty folder.
        video: include the camera frames the runs kept (``record_video``); runs without them
            export without video.

    Raises:
        ExportError: one line, before anything is written for bad input (a run being written,
        a corrupt history, incompatible runs, a non-empty ``out``); nothing is left behind.
    """
    out = Path(out)
    check_out(out)
    sources = [open_source(r) for r in runs]
    fps, n_params = _check_compatible(sources)
    with_video = _video_choice(sources, video)
    warnings = [
        f"{s.path}: left out a torn last record ({s.torn_bytes} bytes, the episode a crash "
        "interrupted)"
        for s in sources
        if s.torn_bytes
    ]
    _remove_dead_partials(out)
    tmp = out.parent / f".{out.name}.partial-{os.getpid()}"  # this export's own
    try:
        left_out: list[str] = []
        summary = _write(sources, tmp, fps, n_params, with_video, left_out)
        try:
            os.rename(tmp, out)  # onto a missing or empty folder only (POSIX)
        except OSError as exc:
            if exc.errno not in (errno.ENOTEMPTY, errno.EEXIST, errno.ENOTDIR):
                raise
            raise ExportError(
                f"{out} was written by another export meanwhile: this one wrote nothing (give "
                "another --out)"
            ) from None
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    summary.out = out
    summary.warnings = warnings + left_out
    return summary


class _Columns:
    """Per-frame and per-episode columns, gathered episode by episode."""

    def __init__(self) -> None:
        self.frames: dict[str, list[np.ndarray]] = {}
        self.episodes: list[dict[str, Any]] = []

    def add(self, key: str, values: np.ndarray) -> None:
        self.frames.setdefault(key, []).append(np.asarray(values))

    def array(self, key: str) -> np.ndarray:
        return np.concatenate(self.frames[key])


def _write(
    sources: list[RunSource],
    root: Path,
    fps: int,
    n_params: int,
    with_video: bool,
    left_out: list[str],
) -> ExportSummary:
    root.mkdir(parents=True)
    cols = _Columns()
    tasks: dict[str, int] = {}
    dims: tuple[int, int] | None = None
    side = 0
    writer = None
    image_stats = _ImageStats()
    index = 0
    names = run_names([s.path for s in sources])
    try:
        for source, name in zip(sources, names, strict=True):
            for ep in iter_episodes(source, with_video, left_out if with_video else None):
                shape = (ep.goal.size, ep.context.size)
                if dims is None:
                    dims = shape
                elif shape != dims:
                    raise ExportError(
                        f"{source.path} has a goal space of {shape[0]} dimensions (context "
                        f"{shape[1]}) and an earlier run {dims[0]} ({dims[1]}): export them apart"
                    )
                if with_video:
                    assert ep.frames is not None
                    if writer is None:
                        side = ep.frames.shape[1]
                        writer = _open_video(root, fps, side)
                    if ep.frames.shape[1:] != (side, side, 3):
                        raise ExportError(
                            f"{source.path}: frames of {ep.frames.shape[1]} px, other runs "
                            f"{side} px: export them apart"
                        )
                    span = writer.add(ep.frames)
                    image_stats.add(ep.frames)
                else:
                    span = None
                task = tasks.setdefault(ep.task, len(tasks))
                _add_episode(cols, ep, len(cols.episodes), index, task, fps, span, source, name)
                index += ep.length
    finally:
        if writer is not None:
            writer.close()
    if dims is None:
        raise ExportError("no episode left to export: every one lacks its camera frames")
    feats = features(cols.array("observation.state").shape[1], n_params, *dims, side)
    _write_tables(root, cols, feats, tasks)
    stats = {key: _stats(cols.array(key)) for key in cols.frames}
    if with_video:
        stats[VIDEO_KEY] = image_stats.result()
    _write_json(root / "meta/stats.json", stats, allow_nan=True)  # as LeRobot writes NaN
    info = {
        "codebase_version": CODEBASE_VERSION,
        "robot_type": ROBOT_TYPE,
        "total_episodes": len(cols.episodes),
        "total_frames": index,
        "total_tasks": len(tasks),
        "chunks_size": CHUNKS_SIZE,
        "data_files_size_in_mb": DATA_FILES_SIZE_IN_MB,
        "video_files_size_in_mb": VIDEO_FILES_SIZE_IN_MB,
        "fps": fps,
        "splits": {"train": f"0:{len(cols.episodes)}"},
        "data_path": DATA_PATH,
        "video_path": VIDEO_PATH if with_video else None,
        "features": feats,
    }
    _write_json(root / "meta/info.json", info)
    return ExportSummary(root, len(cols.episodes), index, list(tasks), side)


def _open_video(root: Path, fps: int, side: int) -> Any:
    from explore.export.video import Mp4Writer

    path = root / VIDEO_PATH.format(video_key=VIDEO_KEY, chunk_index=0, file_index=0)
    path.parent.mkdir(parents=True)
    return Mp4Writer(path, fps, side)


def _add_episode(
    cols: _Columns,
    ep: ExportEpisode,
    episode_index: int,
    first_index: int,
    task: int,
    fps: int,
    span: tuple[float, float] | None,
    source: RunSource,
    run_name: str,
) -> None:
    t = ep.length
    frame = np.arange(t)
    cols.add("observation.state", ep.state)
    cols.add("action", ep.action)
    for key, value in (
        ("episode.dmp_parameters", ep.theta),
        ("episode.goal", ep.goal),
        ("episode.context", ep.context),
        ("episode.outcome", ep.outcome),
    ):
        cols.add(key, np.repeat(np.asarray(value, dtype=float)[None], t, axis=0))
    cols.add("timestamp", frame / fps)
    cols.add("frame_index", frame)
    cols.add("episode_index", np.full(t, episode_index))
    cols.add("index", first_index + frame)
    cols.add("task_index", np.full(t, task))
    row: dict[str, Any] = {
        "episode_index": episode_index,
        "tasks": [ep.task],
        "length": t,
        "data/chunk_index": 0,
        "data/file_index": 0,
        "dataset_from_index": first_index,
        "dataset_to_index": first_index + t,
    }
    if span is not None:
        row[f"videos/{VIDEO_KEY}/chunk_index"] = 0
        row[f"videos/{VIDEO_KEY}/file_index"] = 0
        row[f"videos/{VIDEO_KEY}/from_timestamp"] = span[0]
        row[f"videos/{VIDEO_KEY}/to_timestamp"] = span[1]
    row["meta/episodes/chunk_index"] = 0
    row["meta/episodes/file_index"] = 0
    row["ergo/run"] = run_name
    row["ergo/episode"] = ep.episode
    row["ergo/strategy"] = source.config.strategy.name
    row["ergo/seed"] = source.config.seed
    cols.episodes.append(row)


def _write_tables(
    root: Path, cols: _Columns, feats: dict[str, dict[str, Any]], tasks: dict[str, int]
) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    arrays = {}
    for key, ft in feats.items():
        if ft["dtype"] == "video":
            continue
        values = cols.array(key)
        if ft["shape"] == [1]:
            arrays[key] = pa.array(values.astype(ft["dtype"]))
        else:
            flat = pa.array(values.astype(np.float32).ravel())
            arrays[key] = pa.FixedSizeListArray.from_arrays(flat, ft["shape"][0])
    data = root / DATA_PATH.format(chunk_index=0, file_index=0)
    data.parent.mkdir(parents=True)
    pq.write_table(pa.table(arrays), data)

    int64 = {k for k, v in cols.episodes[0].items() if isinstance(v, int | np.integer)}
    episodes = {}
    for key in cols.episodes[0]:
        values = [row[key] for row in cols.episodes]
        if key == "tasks":
            episodes[key] = pa.array(values, pa.list_(pa.string()))
        elif key in int64:
            episodes[key] = pa.array(values, pa.int64())
        elif isinstance(values[0], float):
            episodes[key] = pa.array(values, pa.float64())
        else:
            episodes[key] = pa.array(values, pa.string())
    path = root / EPISODES_PATH
    path.parent.mkdir(parents=True)
    pq.write_table(pa.table(episodes), path)

    # as pandas writes LeRobot's DataFrame of tasks (the task as its index): pandas gets the
    # index back, other readers see the columns task_index and task
    table = pa.table(
        {
            "task_index": pa.array(list(tasks.values()), pa.int64()),
            "task": pa.array(list(tasks), pa.string()),
        }
    )
    pandas_meta = {
        "index_columns": ["task"],
        "column_indexes": [],
        "columns": [
            {"name": "task_index", "field_name": "task_index", "pandas_type": "int64",
             "numpy_type": "int64", "metadata": None},
            {"name": "task", "field_name": "task", "pandas_type": "unicode",
             "numpy_type": "object", "metadata": None},
        ],
        "creator": {"library": "pyarrow", "version": pa.__version__},
        "pandas_version": "2.2.3",
    }  # fmt: skip
    table = table.replace_schema_metadata({b"pandas": json.dumps(pandas_meta).encode()})
    pq.write_table(table, root / "meta/tasks.parquet")


def _stats(values: np.ndarray) -> dict[str, list[Any]]:
    """LeRobot's statistics of a column over every frame (NaN-aware: NaN where a coordinate is
    never set, which LeRobot's own writer stores as the token ``NaN`` and reads back as a
    number; a ``null`` there made lerobot-train's normalizer fail on the whole file)."""
    v = np.asarray(values, dtype=float).reshape(len(values), -1)
    finite = np.isfinite(v).any(axis=0)
    out: dict[str, list[Any]] = {"count": [len(v)]}
    if not finite.any():
        unset = [float("nan")] * v.shape[1]
        out.update({k: unset for k in ("min", "max", "mean", "std")})
        out.update({f"q{round(q * 100):02d}": unset for q in QUANTILES})
        return out
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN coordinates: NaN
        stats = {
            "min": np.nanmin(v, axis=0),
            "max": np.nanmax(v, axis=0),
            "mean": np.nanmean(v, axis=0),
            "std": np.nanstd(v, axis=0),
        }
        for q in QUANTILES:
            stats[f"q{round(q * 100):02d}"] = np.nanquantile(v, q, axis=0)
    for key, arr in stats.items():
        out[key] = [float(x) for x in arr]
    return out


class _ImageStats:
    """Per-channel statistics of RGB frames scaled to [0, 1], as LeRobot keeps them for a camera
    (shape (3, 1, 1) each), exact: from a histogram of the 256 values of each channel."""

    def __init__(self) -> None:
        self.hist = np.zeros((3, 256), dtype=np.int64)
        self.frames = 0

    def add(self, frames_bgr: np.ndarray) -> None:
        rgb = frames_bgr[..., ::-1].reshape(-1, 3)
        for c in range(3):
            self.hist[c] += np.bincount(rgb[:, c], minlength=256)
        self.frames += len(frames_bgr)

    def result(self) -> dict[str, Any]:
        levels = np.arange(256) / 255.0
        out: dict[str, Any] = {"count": [self.frames]}
        per: dict[str, list[float]] = {k: [] for k in ("min", "max", "mean", "std")}
        quant: dict[str, list[float]] = {f"q{round(q * 100):02d}": [] for q in QUANTILES}
        for h in self.hist:
            n = h.sum()
            seen = np.flatnonzero(h)
            mean = float((h * levels).sum() / n)
            per["min"].append(float(levels[seen[0]]))
            per["max"].append(float(levels[seen[-1]]))
            per["mean"].append(mean)
            per["std"].append(float(np.sqrt((h * (levels - mean) ** 2).sum() / n)))
            cum = np.cumsum(h)
            for q in QUANTILES:
                quant[f"q{round(q * 100):02d}"].append(float(levels[np.searchsorted(cum, q * n)]))
        for key, values in {**per, **quant}.items():
            out[key] = [[[v]] for v in values]
        return out


def _write_json(path: Path, data: Any, allow_nan: bool = False) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(data, indent=2, allow_nan=allow_nan) + "\n")
