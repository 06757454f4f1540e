"""Rerun streaming of an exploration: one ``Recorder`` fed with ``EpisodeRecord``s.

Timelines (every per-episode entity carries both):
- ``episode`` (sequence): the episode index.
- ``time`` (duration, s): robot time since the run began. Episode ``k`` starts where episode
  ``k-1`` ended; its movement ticks are at ``start + reset_s + i / rate_hz`` (i = 0..T-1) and
  the episode's outcome is logged at ``end = start + reset_s + T / rate_hz + settle_s``. On the
  twin this is simulated time, so it does not depend on how fast the machine is.

Entity paths (units: metres, radians, seconds; shapes are per log call):
- ``arena/bounds`` (static) LineStrips2D: the metric's square (the rig's scene's; +-0.2 m on the
  twin).
- ``arena/ball`` Points2D (1,): ball after the episode; orange when it moved, grey otherwise.
- ``arena/ball_track`` LineStrips2D: ball before -> after the episode (empty when not moved).
- ``arena/end_effector`` LineStrips2D (T, 2): tool tip path seen from above (every stride).
- ``arena/end_effector_final`` Points2D (1,): tool tip at the end of the movement.
- ``arm/end_effector`` LineStrips3D (T, 3): tool tip path in 3-D (every stride).
- ``camera/outcome`` EncodedImage (JPEG) 64x64: the outcome observation (every stride).
- ``joints/m1`` .. ``joints/m6`` Scalars (T, 2): commanded target and measured position, rad,
  sent as columns on the ``time`` and ``episode`` timelines (every stride).
- ``goal/target`` Points2D (ceil(g/2),): the goal (g coordinates of the goal space module it
  was sampled in), as consecutive coordinate pairs: 2-D projections of the goal space (a 2-D
  goal is one point; a 10-latent goal is 5 points, one per pair, labelled "z0,z1", ...); only
  when the strategy set a goal.
- ``goal/reached`` Points2D (ceil(g/2),): the episode's outcome in the same module's coordinates,
  paired the same way; ``goal/miss`` LineStrips2D: one segment per pair, goal -> reached;
  ``goal/error`` Scalars: Euclidean distance goal <-> reached (goal-space units). Logged when
  the recorder has ``outcome_of`` (``goal_outcome_of``: the engineered spaces are computed from
  the record; learned ones need the running strategy) or the record an ``outcome`` field.
- ``strategy/module`` Scalars: module index (-1 when none); ``strategy/kind`` TextLog: kind.
- ``stats/ball_cells``, ``stats/ee_cells`` Scalars: distinct cells reached so far (of 30 x 30);
  ``stats/moved_fraction`` Scalars: fraction of episodes so far that moved the ball;
  ``stats/settle_s`` Scalars: how long the ball took to settle; ``stats/episode_wall_s``
  Scalars: wall-clock seconds the episode took.
- ``progress/episodes_per_s`` Scalars: when ``on_progress`` is wired to the explorer.
- ``frames/NAME`` (``log_frame``) and ``series/NAME`` (``log_scalar``): hooks for later data
  (VAE reconstructions, module interests, bus error counters), at the current episode's times.

``rerun`` is imported lazily: importing this module (for ``add_rerun_arguments``) stays cheap.
"""

from __future__ import annotations

import ctypes
import logging
import os
import re
import shutil
import sys
import uuid
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from explore.learner.goal_outcomes import goal_outcome_of, strategy_outcome_of
from explore.learner.scene import Scene
from explore.report.blueprint import default_blueprint
from explore.rigs.episodes import EpisodeConfig
from explore.runs.config import RunConfig
from explore.runs.layout import RECORDING_FILE, RECORDING_NAME, RUN_FILE
from explore.runs.metrics import CellCounter
from robot.spec import ERGO_JR_JOINTS

if TYPE_CHECKING:
    from explore.runs.record import EpisodeRecord

log = logging.getLogger(__name__)

APP_ID = "ergo-explore"
# rerun's own logger reports a file sink's write failure (a full disk) from its writer thread
# in several lines; ``close`` then raises it once, and ``ergo explore`` reports that in its own
# one line. So, unless RUST_LOG says otherwise, those loggers are off (the rest at "warn").
QUIET_FILE_SINK = (
    "warn,re_log_encoding::rrd::file_sink=off,re_log_encoding::rrd::encoder=off,"
    "re_sdk::recording_stream=off"
)
JOINT_NAMES = ERGO_JR_JOINTS
BATCH_FLUSH_S = 1.0  # latency of a live viewer, s
# How long closing waits for a viewer (spawned or connected) to take the last data, s (a guess:
# a live viewer on loopback takes a run's backlog in well under a second). rerun's default
# waits forever: a viewer that never came up (no display) kept `ergo explore` from ending.
VIEWER_FLUSH_S = 10.0
# How long closing waits for the .rrd file to take the last data, s (a guess: the batcher holds
# at most about a second of a run, written in well under a second on any disk). rerun's default
# waits forever: on a full disk the file sink never drains, and `ergo explore` hung after its
# one-line error in 1 run in 4 to 8 (tests/system/test_disk_full.py, a real full disk).
SAVE_FLUSH_S = 10.0
JPEG_QUALITY = 80  # 64x64 frames: about 2 kB each

# Entity paths every recording has (the documented layout; docs/viewing.md).
STATIC_ENTITIES = ("arena/bounds", "arm/bounds")
EPISODE_ENTITIES = (
    "arena/ball",
    "arena/ball_track",
    "arena/end_effector_final",
    "strategy/module",
    "strategy/kind",
    "stats/ball_cells",
    "stats/ee_cells",
    "stats/moved_fraction",
    "stats/settle_s",
    "stats/episode_wall_s",
)
STRIDE_ENTITIES = (
    "arena/end_effector",
    "arm/end_effector",
    "camera/outcome",
    *(f"joints/{name}" for name in JOINT_NAMES),
)
GOAL_ENTITIES = ("goal/target", "goal/reached", "goal/miss", "goal/error")

MOVED_COLOR = (255, 140, 0)
STILL_COLOR = (150, 150, 150)
EE_COLOR = (60, 120, 220)
GOAL_COLOR = (220, 40, 40)
REACHED_COLOR = (40, 170, 60)
MISS_COLOR = (200, 200, 200)
GOAL_RADIUS_UI = -5.0  # goal-space points: 5 UI points whatever the space's scale


def has_display() -> bool:
    """Whether a viewer window can open here."""
    if sys.platform in ("darwin", "win32"):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def viewer_executable() -> str | None:
    """The rerun viewer to start: the one installed beside this Python (a venv's ``bin/``, also
    when the venv is not activated: ``.venv/bin/ergo``), else the one on PATH; None if neither."""
    local = Path(sys.executable).parent / ("rerun.exe" if os.name == "nt" else "rerun")
    return str(local) if local.is_file() else shutil.which("rerun")


# ---- run folder helpers --------------------------------------------------------------------
def recording_paths(run: Path) -> list[Path]:
    """The run's recordings in the order they were written: recording.rrd, recording-2.rrd..."""
    found: list[tuple[int, Path]] = []
    for p in Path(run).glob(f"{RECORDING_NAME}*.rrd"):
        m = re.fullmatch(rf"{RECORDING_NAME}(?:-(\d+))?\.rrd", p.name)
        if m:
            found.append((int(m.group(1) or 1), p))
    return [p for _, p in sorted(found)]


def next_recording_path(run: Path) -> Path:
    """Where a new recording of ``run`` goes: never overwrites an earlier one."""
    existing = recording_paths(run)
    if not existing:
        return Path(run) / RECORDING_FILE
    last = existing[-1].stem.rpartition("-")[2]
    n = int(last) if last.isdigit() else 1
    return Path(run) / f"{RECORDING_NAME}-{n + 1}.rrd"


def run_recording_id(run: Path) -> str:
    """A recording id that is the same for every session of one run, so that the viewer merges
    a run's recording files (a resumed run's new file continues the first one)."""
    created = ""
    meta = Path(run) / RUN_FILE
    if meta.is_file():
        import json

        try:
            created = str(json.loads(meta.read_text()).get("created", ""))
        except (ValueError, OSError):
            created = ""
    return str(uuid.uuid5(uuid.NAMESPACE_URL, f"ergo-explore:{Path(run).resolve()}:{created}"))


# ---- the recorder ----------------------------------------------------------------------------
def pairs(vector: np.ndarray) -> np.ndarray:
    """Consecutive coordinate pairs of a goal-space vector, shape (ceil(g/2), 2) (a trailing
    odd coordinate is paired with 0)."""
    v = np.asarray(vector, dtype=float).ravel()
    if v.size % 2:
        v = np.append(v, 0.0)
    return v.reshape(-1, 2)


def pair_labels(g: int) -> list[str]:
    """Labels of the coordinate pairs of a g-coordinate vector: "z0,z1", "z2,z3", ... (a
    trailing odd coordinate is "z4")."""
    return [f"z{i},z{i + 1}" if i + 1 < g else f"z{i}" for i in range(0, g, 2)]


class Recorder:
    """Streams episodes to rerun (a file, a spawned viewer or a gRPC address on loopback).

    Args:
        sink: ``"save"`` (``path`` required), ``"spawn"`` or ``"connect"`` (``url``).
        path: the ``.rrd`` file for ``"save"``.
        url: gRPC address for ``"connect"``, e.g. ``rerun+http://127.0.0.1:9876/proxy``.
        stride: log the image and the per-tick trajectories every ``stride`` episodes (points
            and scalars are logged every episode).
        rate_hz: control rate, Hz (places the trajectory ticks on the ``time`` timeline).
        reset_s: time the rest pose takes before each movement, s.
        recording_id: rerun recording id (use ``run_recording_id`` to merge a run's files).
        outcome_of: maps a record to its outcome in the coordinates of its goal (the module
            it was sampled in), shape like ``record.goal``, or None (``strategy_outcome_of``,
            ``goal_outcome_of``); without it, a record's ``outcome`` attribute if it has one.
        blueprint: send the default layout (``default_blueprint``).
        scene: the rig's scene (the metric's squares; ``explore.rigs.rig.rig_scene``).
    """

    def __init__(
        self,
        sink: str = "save",
        path: Path | None = None,
        url: str | None = None,
        stride: int = 1,
        rate_hz: float = EpisodeConfig.rate_hz,
        reset_s: float = EpisodeConfig.reset_s,
        recording_id: str | None = None,
        outcome_of: Callable[[EpisodeRecord], np.ndarray | None] | None = None,
        blueprint: bool = True,
        *,
        scene: Scene,
    ) -> None:
        os.environ.setdefault("RUST_LOG", QUIET_FILE_SINK)
        import rerun as rr

        if stride < 1:
            raise ValueError(f"stride must be at least 1, got {stride}")
        self._rr = rr
        self.stride = stride
        self.dt = 1.0 / rate_hz
        self.reset_s = reset_s
        self.outcome_of = outcome_of
        self.path = Path(path) if path is not None else None
        self.sink = sink
        self.scene = scene
        self.ball_cells = CellCounter(scene.ball_half_width)
        self.ee_cells = CellCounter(scene.hand_half_width)
        self.n_episodes = 0
        self.n_moved = 0
        self.clock_s = 0.0  # robot time at the end of the last episode
        self.episode = -1
        self._closed = False
        # Episodes last seconds: batch chunks over BATCH_FLUSH_S rather than rerun's default
        # 200 ms, which would cut one small chunk per entity per episode (bigger files, more CPU).
        batcher = rr.ChunkBatcherConfig(flush_tick=BATCH_FLUSH_S)
        self.rec = rr.RecordingStream(APP_ID, recording_id=recording_id, batcher_config=batcher)
        bp = (
            default_blueprint(scene.ball_half_width, goals=outcome_of is not None)
            if blueprint
            else None
        )
        if sink == "save":
            if self.path is None:
                raise ValueError("sink 'save' needs a path")
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self.rec.save(self.path, default_blueprint=bp)
        elif sink == "spawn":
            rr.spawn(executable_path=viewer_executable(), recording=self.rec, default_blueprint=bp)
        elif sink == "connect":
            self.rec.connect_grpc(url, default_blueprint=bp)
        else:
            raise ValueError(f"unknown rerun sink {sink!r} (save, spawn or connect)")
        self._log_static()

    # ---- static content --------------------------------------------------------------------
    def _log_static(self) -> None:
        rr, h = self._rr, self.scene.ball_half_width
        square = [[-h, -h], [h, -h], [h, h], [-h, h], [-h, -h]]
        self.rec.log(
            "arena/bounds",
            rr.LineStrips2D([square], colors=[(90, 90, 90)], radii=0.001),
            static=True,
        )
        self.rec.log(
            "arm/bounds",
            rr.LineStrips3D([[[x, y, 0.0] for x, y in square]], colors=[(90, 90, 90)]),
            static=True,
        )
        colors = [(31, 119, 180), (255, 127, 14)]
        for name in JOINT_NAMES:
            self.rec.log(
                f"joints/{name}",
                rr.SeriesLines(names=[f"{name} target", f"{name} measured"], colors=colors),
                static=True,
            )

    # ---- per episode -----------------------------------------------------------------------
    def _advance(self, rec: EpisodeRecord) -> tuple[float, float]:
        """Book-keeping of one episode (cells, clock); returns (movement start, end) times, s."""
        start = self.clock_s + self.reset_s
        end = start + len(rec.targets) * self.dt + float(rec.settle_s)
        self.clock_s = end
        self.episode = rec.episode
        self.n_episodes += 1
        self.n_moved += int(rec.ball_moved)
        self.ball_cells.add(rec.ball)
        self.ee_cells.add(np.asarray(rec.end_effector)[-1:, :2])
        return start, end

    def prime(self, records: Iterable[EpisodeRecord]) -> None:
        """Catch up with episodes recorded before (a resumed run) without logging them."""
        for rec in records:
            self._advance(rec)

    def _set_times(self) -> None:
        self.rec.set_time("episode", sequence=max(self.episode, 0))
        self.rec.set_time("time", duration=self.clock_s)

    def on_record(self, rec: EpisodeRecord) -> None:
        """Log one episode (the explorer's ``on_record`` callback)."""
        rr = self._rr
        start, _ = self._advance(rec)
        self._set_times()
        k = rec.episode
        ball = np.asarray(rec.ball, dtype=float)
        ee = np.asarray(rec.end_effector, dtype=float)
        if np.all(np.isfinite(ball)):
            color = MOVED_COLOR if rec.ball_moved else STILL_COLOR
            self.rec.log("arena/ball", rr.Points2D([ball], colors=[color], radii=0.006))
        track = np.stack([np.asarray(rec.context_ball, dtype=float), ball])
        if rec.ball_moved and np.all(np.isfinite(track)):
            self.rec.log("arena/ball_track", rr.LineStrips2D([track], colors=[MOVED_COLOR]))
        else:
            self.rec.log("arena/ball_track", rr.LineStrips2D([]))
        if np.all(np.isfinite(ee[-1])):
            self.rec.log(
                "arena/end_effector_final",
                rr.Points2D([ee[-1, :2]], colors=[EE_COLOR], radii=0.003),
            )
        self._log_goal(rec)
        self.rec.log("strategy/module", rr.Scalars(float(rec.module)))
        self.rec.log("strategy/kind", rr.TextLog(f"episode {k}: {rec.kind}, module {rec.module}"))
        self.rec.log("stats/ball_cells", rr.Scalars(float(self.ball_cells.count)))
        self.rec.log("stats/ee_cells", rr.Scalars(float(self.ee_cells.count)))
        self.rec.log("stats/moved_fraction", rr.Scalars(self.n_moved / self.n_episodes))
        self.rec.log("stats/settle_s", rr.Scalars(float(rec.settle_s)))
        self.rec.log("stats/episode_wall_s", rr.Scalars(float(rec.duration_s)))
        if k % self.stride == 0:
            self._log_heavy(rec, start)

    def _log_goal(self, rec: EpisodeRecord) -> None:
        """The goal, the reached outcome and the miss, as coordinate pairs of the goal space."""
        rr = self._rr
        goal = np.asarray(rec.goal, dtype=float).ravel()
        if goal.size == 0:
            return
        labels = pair_labels(goal.size)
        self.rec.log(
            "goal/target",
            rr.Points2D(pairs(goal), colors=[GOAL_COLOR], radii=GOAL_RADIUS_UI, labels=labels),
        )
        reached = self.outcome_of(rec) if self.outcome_of else getattr(rec, "outcome", None)
        if reached is None:
            return
        reached = np.asarray(reached, dtype=float).ravel()
        if reached.shape != goal.shape or not np.all(np.isfinite(reached)):
            return
        self.rec.log(
            "goal/reached",
            rr.Points2D(pairs(reached), colors=[REACHED_COLOR], radii=GOAL_RADIUS_UI),
        )
        self.rec.log(
            "goal/miss",
            rr.LineStrips2D(np.stack([pairs(goal), pairs(reached)], axis=1), colors=[MISS_COLOR]),
        )
        self.rec.log("goal/error", rr.Scalars(float(np.linalg.norm(reached - goal))))

    def _log_heavy(self, rec: EpisodeRecord, start: float) -> None:
        """The image and the per-tick trajectories (every ``stride`` episodes)."""
        rr = self._rr
        ee = np.asarray(rec.end_effector, dtype=float)
        self.rec.log("arena/end_effector", rr.LineStrips2D([ee[:, :2]], colors=[EE_COLOR]))
        self.rec.log("arm/end_effector", rr.LineStrips3D([ee], colors=[EE_COLOR]))
        image = np.asarray(rec.image)
        if image.ndim == 3 and image.size:
            self.rec.log(
                "camera/outcome",
                rr.Image(image, color_model="BGR").compress(jpeg_quality=JPEG_QUALITY),
            )
        targets = np.asarray(rec.targets, dtype=float)
        measured = np.asarray(rec.measured, dtype=float)
        n = len(targets)
        if n == 0 or measured.shape != targets.shape:
            return
        indexes = [
            rr.TimeColumn("time", duration=start + np.arange(n) * self.dt),
            rr.TimeColumn("episode", sequence=np.full(n, rec.episode)),
        ]
        for j, name in enumerate(JOINT_NAMES[: targets.shape[1]]):
            both = np.stack([targets[:, j], measured[:, j]], axis=1)
            self.rec.send_columns(
                f"joints/{name}", indexes=indexes, columns=rr.Scalars.columns(scalars=both)
            )

    def on_progress(self, progress: Any) -> None:
        """Optional: the explorer's ``on_episode`` callback (``explorer.Progress``)."""
        self._set_times()
        self.rec.log("progress/episodes_per_s", self._rr.Scalars(float(progress.episodes_per_s)))

    # ---- hooks for later data --------------------------------------------------------------
    def log_frame(self, name: str, image: np.ndarray, bgr: bool = True) -> None:
        """Log an image under ``frames/NAME`` at the current episode (JPEG).

        Args:
            name: entity name below ``frames/`` ("vae/reconstruction"; slashes nest).
            image: (H, W, 3) uint8 (BGR unless ``bgr`` is False), or (H, W) grey, or float in
                [0, 1] (converted to uint8).
        """
        rr = self._rr
        img = np.asarray(image)
        if img.dtype != np.uint8:
            img = (np.clip(img, 0.0, 1.0) * 255).astype(np.uint8)
        self._set_times()
        kw = {"color_model": "BGR" if bgr else "RGB"} if img.ndim == 3 else {"color_model": "L"}
        self.rec.log(f"frames/{name}", rr.Image(img, **kw).compress(jpeg_quality=JPEG_QUALITY))

    def log_scalar(self, name: str, value: float) -> None:
        """Log a number under ``series/NAME`` at the current episode ("interest/module3",
        "bus/no_status_packets"). Callable from any thread."""
        self._set_times()
        self.rec.log(f"series/{name}", self._rr.Scalars(float(value)))

    def close(self) -> None:
        """Flush and close the sink (the ``.rrd`` is complete afterwards; a file gets
        ``SAVE_FLUSH_S`` and a viewer ``VIEWER_FLUSH_S`` to take the last data, after which
        rerun raises: a full disk never takes it)."""
        if self._closed:
            return
        self._closed = True
        try:
            self.rec.flush(timeout_sec=SAVE_FLUSH_S if self.sink == "save" else VIEWER_FLUSH_S)
        except BaseException:
            # A sink that did not drain (a full disk, a viewer gone): rerun's disconnect, its exit
            # hook and the stream's own __del__ (which disconnects it) would each wait for it
            # again, for ever. The stream is kept alive to the end of the process (one reference
            # never given back) and the exit hook removed, so the process can end.
            self._rr.unregister_shutdown()
            ctypes.pythonapi.Py_IncRef(ctypes.py_object(self.rec))
            raise
        self.rec.disconnect()

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


# ---- opening one for a run -------------------------------------------------------------------
def open_recorder(
    run_path: Path,
    mode: str = "save",
    url: str | None = None,
    stride: int = 1,
    records: Iterable[EpisodeRecord] | None = None,
    config: RunConfig | None = None,
    strategy: Any = None,
    load_models: bool = False,
) -> Recorder | None:
    """The recorder of a run: into its next ``recording-N.rrd`` (``mode`` "save"), a spawned
    viewer ("spawn") or a running viewer at ``url``; None for ``mode`` "off" without a url.

    Args:
        run_path: the run folder (already created).
        stride: log images and trajectories every ``stride`` episodes (>= 1).
        records: episodes already in the run (a resume), to continue the cell counts and the
            clock; read from ``run_path`` when None.
        config: the run's config; read from ``run_path`` (its ``run.json``) when None.
        strategy: the running strategy: its goal space gives ``goal/reached`` for every
            strategy with one (learned spaces included). Without it, only the spaces that
            ``goal_outcome_of(config.strategy, load_models)`` can build.
        load_models: without ``strategy``, also load a learned goal space's model.
    """
    if mode == "off" and url is None:
        return None
    run_path = Path(run_path)
    if config is None:
        from explore.runs.store import RunStore

        config = RunConfig.of_run(RunStore.read_meta(run_path)["config"], run_path / RUN_FILE)
    from explore.rigs.rig import rig_scene

    scene = rig_scene(config.rig)
    kw: dict[str, Any] = {
        "scene": scene,
        "stride": stride,
        "rate_hz": float(config.episode.rate_hz),
        "reset_s": float(config.episode.reset_s),
        "recording_id": run_recording_id(run_path),
        "outcome_of": (
            strategy_outcome_of(strategy)
            if strategy is not None
            else goal_outcome_of(config.strategy.to_dict(), load_models=load_models, scene=scene)
        ),
    }
    if url is not None:
        recorder = Recorder("connect", url=url, **kw)
    elif mode == "spawn":
        recorder = Recorder("spawn", **kw)
    else:
        recorder = Recorder("save", path=next_recording_path(run_path), **kw)
    if records is None:
        from explore.runs.store import iter_history

        records = iter_history(run_path)
    recorder.prime(records)
    return recorder
