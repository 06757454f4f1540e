"""``ergo sim view`` (PNG of the twin's cameras) and ``ergo twin serve`` (the twin behind a
real bus protocol, in real time, for hardware-in-the-loop tests)."""

from __future__ import annotations

import argparse
from pathlib import Path

from plumbing.registry import LazyTable

# --bus NAME -> "module:function(args) -> int" that serves until interrupted.
BUS_SERVERS = LazyTable(
    "bus server", {"dynamixel": "sim.dynamixel.server:serve", "canopen": "sim.canopen.server:serve"}
)


def register(sub: argparse._SubParsersAction) -> None:
    p_sim = sub.add_parser("sim", help="the MuJoCo twin: views")
    sim_sub = p_sim.add_subparsers(dest="sim_command", metavar="SUBCOMMAND")
    sim_sub.required = True
    view = sim_sub.add_parser("view", help="write PNGs of the overhead and side cameras")
    view.add_argument("--out", type=Path, default=Path("twin.png"), help="overhead PNG path")
    view.add_argument("--size", type=int, default=480, help="image side, pixels")
    view.add_argument("--pose", type=float, nargs=6, metavar="RAD", help="joint angles, rad")
    view.set_defaults(func=_view)

    p_twin = sub.add_parser("twin", help="serve the twin behind a bus protocol")
    twin_sub = p_twin.add_subparsers(dest="twin_command", metavar="SUBCOMMAND")
    twin_sub.required = True
    serve = twin_sub.add_parser(
        "serve", help="emulate the arm's servos on a pseudo-terminal (and the camera over HTTP)"
    )
    serve.add_argument("--bus", choices=sorted(BUS_SERVERS), required=True)
    serve.add_argument("--speed", type=float, default=1.0, help="simulated s per wall s")
    serve.add_argument("--camera-port", type=int, default=0, help="MJPEG port (0: any free)")
    serve.add_argument("--no-camera", action="store_true", help="do not serve the camera")
    serve.add_argument("--drop-rate", type=float, default=0.0, help="fraction of replies lost")
    serve.add_argument("--corrupt-rate", type=float, default=0.0, help="fraction corrupted")
    serve.add_argument("--delay-ms", type=float, default=0.0, help="extra reply delay, ms")
    serve.add_argument(
        "--late-rate", type=float, default=0.0,
        help="dynamixel: fraction of replies sent after the host's timeout",
    )  # fmt: skip
    serve.add_argument(
        "--link", type=Path, default=None, metavar="PATH",
        help="keep a symbolic link PATH to the current pty (a stable name across unplug/replug)",
    )  # fmt: skip
    serve.add_argument("--overload-servo", type=int, default=None, help="id that raises alerts")
    serve.add_argument(
        "--overload-after", dest="overload_after_s", type=float, default=2.0, metavar="S",
        help="with --overload-servo: seconds of torque before the alert (default 2)",
    )  # fmt: skip
    serve.add_argument("--seed", type=int, default=0, help="fault injection seed")
    serve.add_argument(
        "--stand-in", type=int, default=None, metavar="SEED",
        help="serve a rig the software has never seen: servo offsets and directions, the "
        "camera's pose and lens, the servos' dynamics and the ball drawn from SEED "
        "(docs/standin.md)",
    )  # fmt: skip
    serve.add_argument(
        "--hidden", type=Path, default=None, metavar="PATH",
        help="with --stand-in: write the hidden parameters here (default: a file per seed in "
        "the temporary folder; for tests, never read by a calibration)",
    )  # fmt: skip
    serve.add_argument(
        "--zero-marks", choices=("horn", "anywhere"), default="horn",
        help="with --stand-in on canopen: where the drives' encoders read each joint's zero "
        "mark: a few degrees off (horn, the default) or anywhere on the turn and up to two "
        "turns beyond (anywhere; docs/standin.md)",
    )  # fmt: skip
    serve.add_argument(
        "--heartbeats", choices=("process", "threads"), default="process",
        help="canopen: the drives' heartbeats from a process of their own (the default: on time "
        "whatever the server does) or from the server's threads (for comparison; "
        "docs/canopen.md)",
    )  # fmt: skip
    serve.add_argument(
        "--rig-id", default=None, metavar="ID",
        help="the twin's servos fitted to rig ID's arm (its dynamics.json, `ergo calibrate "
        "dynamics`; ERGO_CALIBRATION_DIR); without the file, the nominal servos (docs/dynamics.md)",
    )  # fmt: skip
    serve.add_argument(
        "--floor-rgb", type=float, nargs=3, default=None, metavar=("R", "G", "B"),
        help="the arena's floor (and kerb) in this colour, each 0..1 (default: the twin's blue; "
        "docs/calibration.md)",
    )  # fmt: skip
    serve.add_argument(
        "--hands-port", type=int, default=0,
        help="port of the hands' control channel on 127.0.0.1 (0: any free; docs/standin.md)",
    )  # fmt: skip
    serve.set_defaults(func=_serve)


def _view(args: argparse.Namespace) -> int:
    import cv2
    import numpy as np

    from sim.twin import Twin

    twin = Twin(render_size=(args.size, args.size))
    if args.pose is not None:
        q = np.asarray(args.pose)
        twin.set_targets(q)
        twin.data.qpos[twin._qpos_idx] = q
    twin.step(0.5)
    out: Path = args.out
    out.parent.mkdir(parents=True, exist_ok=True)
    side = out.with_name(out.stem + "_side" + out.suffix)
    cv2.imwrite(str(out), twin.render("overhead"))
    cv2.imwrite(str(side), twin.render("side"))
    print(f"wrote {out} and {side}")
    return 0


def _serve(args: argparse.Namespace) -> int:
    return int(BUS_SERVERS.load(args.bus)(args) or 0)
