"""The ``dynamixel`` rig: a real (or emulated) Ergo Jr on a serial port, an OpenCV camera and
the wall clock.

Options (``RigConfig.options``):
    port: serial device of the Dynamixel bus, e.g. ``/dev/ttyUSB0`` or the pty printed by
        ``ergo twin serve --bus dynamixel`` (required).
    baud: bit/s (default 1_000_000, the Ergo Jr's XL-320 setting).
    camera: device index (``0``) or URL/path (``http://127.0.0.1:PORT/stream.mjpg``); default 0.
    camera_width, camera_height, camera_fps: requested camera mode (optional).
    model: servo model (default "XL-320").
    directions, offsets: per joint +1/-1 and rad (default +1 and 0; the calibration sets them).
    latency_s: slack added to every bus timeout, s (default 0.020, see
        ``robot.dynamixel.bus.DEFAULT_LATENCY_S``; more for an emulator on a loaded machine).
    retries: retries per bus call after a lost or corrupt reply (default 2).
"""

from __future__ import annotations

import importlib
from typing import Any

from explore.rigs.ball import rig_ball_locator
from explore.rigs.clock import RealClock
from explore.rigs.rig import Rig, RigConfig, RigError


def _camera(options: dict[str, Any]) -> Any:
    source = options.get("camera", 0)
    if isinstance(source, str) and source.strip().isdigit():
        source = int(source)
    if not isinstance(source, int | str) or isinstance(source, bool):
        raise RigError(f"dynamixel rig: camera must be a device index or a URL, got {source!r}")
    try:
        module = importlib.import_module("vision.opencv_camera")
    except ImportError as exc:
        raise RigError(f"dynamixel rig: the OpenCV camera is unavailable ({exc})") from exc
    return module.OpenCVCamera(
        source,
        width=options.get("camera_width"),
        height=options.get("camera_height"),
        fps=options.get("camera_fps"),
    )


def make_dynamixel_rig(config: RigConfig) -> Rig:
    """Build (not connect) the rig from ``config.options`` (see the module docstring)."""
    from robot.dynamixel.arm import DynamixelArm
    from robot.errors import BusError

    options = dict(config.options)
    port = options.get("port")
    if not port:
        raise RigError(
            "dynamixel rig needs options.port, the serial port of the servos (e.g. /dev/ttyUSB0, "
            "or the pty printed by `ergo twin serve --bus dynamixel`)"
        )
    try:
        baud = int(options.get("baud", 1_000_000))
        bus: dict[str, Any] = {}
        if options.get("latency_s") is not None:
            bus["latency_s"] = float(options["latency_s"])
        if options.get("retries") is not None:
            bus["retries"] = int(options["retries"])
        arm = DynamixelArm(
            str(port),
            baud,
            model=options.get("model", "XL-320"),
            directions=options.get("directions"),
            offsets=options.get("offsets"),
            **bus,
        )
    except (ValueError, KeyError, TypeError, BusError) as exc:
        raise RigError(f"dynamixel rig: {exc}") from exc
    return Rig(
        arm=arm, camera=_camera(options), clock=RealClock(), config=config, twin=None,
        ball_locator=rig_ball_locator(config),
    )  # fmt: skip
