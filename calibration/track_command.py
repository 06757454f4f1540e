"""``ergo track``: the ball tracker live, one line per frame, in pixels or, with ``--arena``,
in metres; here, beside the calibration commands, because ``--arena`` reads an arena
calibration file (checked against its ``camera.json``), which ``vision/`` may not import."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from plumbing.cli_errors import error


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``ergo track`` to the root's subcommands."""
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
    track.set_defaults(func=run_track)


def run_track(args: argparse.Namespace) -> int:
    import dataclasses

    from vision.camera import CameraError, EndOfStream
    from vision.make_camera import make_camera
    from vision.rectify import ArenaModel
    from vision.tracker import BallTracker, HSVRange, TrackerConfig, tracker_config_from_arena

    arena, config = None, TrackerConfig()
    if args.arena is not None:
        from calibration import store

        try:  # validated (version, finite numbers) and checked against camera.json beside it
            data = store.load_arena_file(args.arena)
        except store.CalibrationError as exc:
            return error(exc)
        arena = ArenaModel.from_dict(data)
        config = tracker_config_from_arena(data)
    if args.hsv:
        try:
            ranges = tuple(HSVRange.parse(h) for h in args.hsv)
        except ValueError as exc:
            return error(f"--hsv: {exc}")
        config = dataclasses.replace(config, ranges=ranges)
    tracker = BallTracker(config, arena)
    try:
        camera = make_camera(args.camera, args.width, args.height, args.fps, args.fourcc)
    except CameraError as exc:
        return error(exc)
    n = 0
    try:
        with camera:
            for warning in getattr(camera, "settings_warnings", []):
                print(f"warning: camera ignored a setting: {warning}", file=sys.stderr)
            while args.frames is None or n < args.frames:
                try:
                    frame = camera.read()
                except EndOfStream:
                    if n:  # a recording played to its end (none at all: an error)
                        break
                    raise
                obs = tracker.track(frame.image)
                print(f"frame {n} t={frame.timestamp:.3f}s: {obs.describe()}", flush=True)
                n += 1
    except CameraError as exc:
        return error(exc)
    except KeyboardInterrupt:
        pass
    return 0
