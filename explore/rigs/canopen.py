"""The ``canopen`` rig: six CiA 402 drives on a CAN bus (``CanArm``), a camera (OpenCV device
index, file or URL) and the wall clock.

Options (``RigConfig.options``):
    can: python-can bus ``INTERFACE:CHANNEL`` (required), e.g. ``socketcan:can0``,
        ``slcan:/dev/ttyACM0``, or ``slcan:/dev/pts/N`` from ``ergo twin serve --bus canopen``.
    bitrate: CAN bit/s for interfaces that take one (default 1000000).
    camera: device index, video path or URL (default 0), e.g.
        ``http://127.0.0.1:PORT/stream.mjpg`` from ``ergo twin serve``.
    camera_width, camera_height, camera_fps: requested camera mode (optional).
    node_ids: the six node ids of m1..m6 (default 1..6).
    directions, offsets: per joint (+1/-1, rad), see ``robot.canopen.units``.
    eds: the drives' EDS file (default: ``robot/canopen/ergo_drive.eds``, the emulated drive).
    pdo_timeout_s, following_error_window: see ``robot.canopen.arm.CanArmConfig``.
    heartbeat_ms: producer heartbeat time written to the drives, ms (default 100 on a real
        adapter; 500 on a pty, i.e. the emulator, whose heartbeats cross several Python threads
        on a shared machine: gaps over 150 ms were seen with the camera rendering under load).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from explore.rigs.ball import rig_ball_locator
from explore.rigs.clock import RealClock
from explore.rigs.rig import Rig, RigConfig, RigError

# Heartbeat time for the emulator on a pty, ms (see the module docstring; a guess with margin).
PTY_HEARTBEAT_MS = 500
# Options passed through to ``CanArmConfig`` as tuples (lists in JSON).
_TUPLE_OPTIONS = ("node_ids", "directions", "offsets")
_SCALAR_OPTIONS = {
    "heartbeat_ms": int,
    "pdo_timeout_s": float,
    "following_error_window": float,
    "eds": Path,
}
_CAMERA_OPTIONS = ("camera", "camera_width", "camera_height", "camera_fps")
KNOWN_OPTIONS = {"can", "bitrate", *_CAMERA_OPTIONS, *_TUPLE_OPTIONS, *_SCALAR_OPTIONS}


def _arm_config(options: dict[str, Any]) -> dict[str, Any]:
    cfg: dict[str, Any] = {}
    for key in _TUPLE_OPTIONS:
        if options.get(key) is not None:
            value = options[key]
            if not isinstance(value, list | tuple) or len(value) != 6:
                raise RigError(f"rig 'canopen': option {key} needs 6 values, got {value!r}")
            cfg[key] = tuple(int(v) if key == "node_ids" else float(v) for v in value)
    for key, kind in _SCALAR_OPTIONS.items():
        if options.get(key) is not None:
            try:
                cfg[key] = kind(options[key])
            except (TypeError, ValueError) as exc:
                raise RigError(f"rig 'canopen': option {key}={options[key]!r}: {exc}") from exc
    return cfg


def make_canopen_rig(config: RigConfig) -> Rig:
    """Build (not connect) the rig; bad or missing options are one-line ``RigError``s."""
    from robot.canopen.arm import CanArm, CanArmConfig
    from robot.canopen.bus import CanBusError, parse_can_spec

    options = dict(config.options)
    unknown = sorted(set(options) - KNOWN_OPTIONS)
    if unknown:
        raise RigError(f"rig 'canopen': unknown option(s) {', '.join(unknown)}")
    can = options.get("can")
    if not can:
        raise RigError(
            "rig 'canopen' needs option can: INTERFACE:CHANNEL, e.g. --can socketcan:can0 or "
            "--can slcan:/dev/ttyACM0"
        )
    source = options.get("camera", 0)
    if isinstance(source, str) and source.strip().isdigit():
        source = int(source)
    if not isinstance(source, int | str) or isinstance(source, bool) or source == "":
        raise RigError(
            f"rig 'canopen': camera must be a device index, video path or URL, got {source!r}"
        )
    bitrate = options.get("bitrate")
    if options.get("heartbeat_ms") is None and "/dev/pts/" in str(can):
        options["heartbeat_ms"] = PTY_HEARTBEAT_MS
    try:
        spec = parse_can_spec(str(can), int(bitrate) if bitrate is not None else None)
        arm = CanArm(spec, config=CanArmConfig(**_arm_config(options)))
    except (CanBusError, ValueError) as exc:
        raise RigError(f"rig 'canopen': {exc}") from exc
    try:
        from vision.opencv_camera import OpenCVCamera
    except ImportError as exc:
        raise RigError(f"rig 'canopen' needs vision.opencv_camera: {exc}") from exc
    camera = OpenCVCamera(
        source,
        width=options.get("camera_width"),
        height=options.get("camera_height"),
        fps=options.get("camera_fps"),
    )
    return Rig(
        arm=arm, camera=camera, clock=RealClock(), config=config,
        ball_locator=rig_ball_locator(config),
    )  # fmt: skip
