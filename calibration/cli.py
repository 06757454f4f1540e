"""``ergo calibrate camera | arena | joints | show``: make and check the calibration files of a
rig (``calibration.store``). Heavy imports (OpenCV, robot backends) happen inside commands."""

from __future__ import annotations

import argparse
import functools
import math
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

from plumbing.cli_errors import error
from robot.bus_flags import add_bus_arguments, bus_from_args, make_arm
from sim.models.make_scene import BALL_RADIUS

DEFAULT_VIEWS = 15  # views to collect from a live camera (OpenCV's tutorial: 10-15, docs/facts.md)
MIN_VIEW_SHIFT_PX = 25.0  # a live view is kept only if the corners moved this much (guess)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("calibrate", help="camera intrinsics, arena plane, joint offsets")
    cal = p.add_subparsers(dest="calibrate_command", metavar="SUBCOMMAND")
    cal.required = True

    def common(q: argparse.ArgumentParser) -> None:
        q.add_argument(
            "--rig-id", dest="rig_id", default="default", help="rig id (a folder per rig)"
        )
        # ``--rig`` is the rig type in ``ergo explore`` (sim, dynamixel, canopen): here it is
        # refused with a line naming --rig-id, not taken as an abbreviation of it
        q.add_argument("--rig", dest="rig_type", default=None, help=argparse.SUPPRESS)
        q.add_argument(
            "--dir",
            type=Path,
            default=None,
            help="calibration root (default $ERGO_CALIBRATION_DIR or "
            "~/.config/ergo-explore/calibration)",
        )

    cam = cal.add_parser("camera", help="intrinsics from ChArUco or chessboard views")
    common(cam)
    src = cam.add_mutually_exclusive_group()
    src.add_argument("--images", type=Path, help="folder of board images")
    src.add_argument("--camera", help="live camera (device index or URL) or a recorded video")
    cam.add_argument("--views", type=int, default=DEFAULT_VIEWS, help="live views to collect")
    cam.add_argument("--max-frames", type=int, default=3000, help="live frames to look at")
    cam.add_argument(
        "--board", choices=("charuco", "chessboard"), default="charuco",
        help="the target: a ChArUco board (default) or a plain chessboard",
    )  # fmt: skip
    cam.add_argument(
        "--squares", type=int, nargs=2, default=(7, 5), metavar=("COLS", "ROWS"),
        help="squares of the board (a chessboard of 9 x 6 inner corners has 10 x 7)",
    )  # fmt: skip
    cam.add_argument("--square-m", type=float, default=0.030, help="measured square side, m")
    cam.add_argument(
        "--marker-m", type=float, default=0.022, help="ChArUco: measured marker side, m"
    )
    cam.add_argument("--dictionary", default="DICT_5X5_100", help="ChArUco: cv2.aruco dictionary")
    cam.add_argument("--fit-k3", action="store_true", help="also fit the k3 radial term")
    cam.add_argument("--print-board", type=Path, metavar="OUT.png", help="write the board")
    cam.add_argument("--dpi", type=float, default=300.0, help="--print-board resolution")
    cam.set_defaults(func=_camera)

    arena = cal.add_parser("arena", help="arena plane, centre, radius and ball colour")
    common(arena)
    asrc = arena.add_mutually_exclusive_group()
    asrc.add_argument("--image", type=Path, help="a saved frame of the arena")
    asrc.add_argument("--camera", help="live camera: device index, URL or video file")
    arena.add_argument(
        "--markers",
        default=None,
        help='ArUco marker centres "ID:X,Y;ID:X,Y;..." in metres (default: the twin layout)',
    )
    arena.add_argument("--marker-size", type=float, default=None, help="marker side, m")
    arena.add_argument("--dictionary", default="DICT_4X4_50", help="cv2.aruco dictionary")
    arena.add_argument(
        "--print-markers", type=Path, metavar="OUT.png",
        help="write the markers to print (A4, with where each goes) and stop unless --image or "
        "--camera is given too",
    )  # fmt: skip
    arena.add_argument("--dpi", type=float, default=300.0, help="--print-markers resolution")
    arena.add_argument(
        "--corners",
        nargs=4,
        metavar="U,V",
        help="instead of markers: four clicked pixels (raw frame) ...",
    )
    arena.add_argument(
        "--corner-xy",
        metavar="X,Y;X,Y;X,Y;X,Y",
        help="... and their arena positions, m (write --corner-xy=... when it starts with -)",
    )
    arena.add_argument(
        "--centre", default="0,0", metavar="X,Y", help="arena centre, m (--centre=-0.1,0)"
    )
    arena.add_argument("--radius", type=float, default=None, help="arena radius, m")
    arena.add_argument("--ball-pixel", metavar="U,V", help="a pixel on the ball (default: find)")
    arena.add_argument("--no-ball", action="store_true", help="do not sample the ball's colour")
    arena.add_argument(
        "--ball-radius",
        type=float,
        default=BALL_RADIUS,
        help="ball radius, m (default: the twin's)",
    )
    arena.add_argument(
        "--fovy",
        type=float,
        default=None,
        help="no camera calibration: assume an ideal pinhole of this vertical FOV, deg",
    )
    arena.set_defaults(func=_arena)

    joints = cal.add_parser("joints", help="joint offsets, directions and ranges, by hand")
    common(joints)
    add_bus_arguments(joints, required=True)
    joints.add_argument("--model", default="XL-320", help="Dynamixel model")
    joints.add_argument("--joints", nargs="*", default=None, help="joint names (default all)")
    joints.set_defaults(func=_joints)

    dyn = cal.add_parser(
        "dynamics", help="the twin's servos fitted to the arm's recorded motion (mujoco.sysid)"
    )
    common(dyn)
    from calibration.dynamics.command import add_arguments as dynamics_arguments

    dynamics_arguments(dyn)
    dyn.set_defaults(func=_dynamics)

    show = cal.add_parser("show", help="validate and summarise a rig's calibration files")
    common(show)
    show.set_defaults(func=_show)

    from calibration.track_command import register as register_track

    register_track(sub)


def _pair(text: str, what: str) -> tuple[float, float]:
    from calibration.store import CalibrationError

    try:
        a, b = (float(v) for v in text.split(","))
    except ValueError:
        raise CalibrationError(f"bad {what} {text!r}: expected two numbers A,B") from None
    return a, b


def _command(func: Callable[[argparse.Namespace], int | None]) -> Callable[..., int]:
    """An ``ergo calibrate`` command: ``--rig`` refused (the rig id is ``--rig-id``), and a
    calibration or camera error said in one line (``ergo: error: ...``)."""

    @functools.wraps(func)
    def command(args: argparse.Namespace) -> int:
        from calibration.store import CalibrationError
        from vision.camera import CameraError

        if args.rig_type is not None:
            return error(
                f"--rig {args.rig_type}: ergo calibrate takes the rig id as --rig-id ID "
                "(--rig is the rig type of ergo explore)"
            )
        try:
            return int(func(args) or 0)
        except (CalibrationError, CameraError) as exc:
            return error(exc)

    return command


# ---- camera ------------------------------------------------------------------------------
@_command
def _camera(args: argparse.Namespace) -> int:
    import cv2

    from calibration import charuco, store
    from calibration.chessboard import ChessboardSpec

    if args.board == "chessboard":
        spec: Any = ChessboardSpec(tuple(args.squares), args.square_m)
    else:
        spec = charuco.BoardSpec(tuple(args.squares), args.square_m, args.marker_m, args.dictionary)
    if args.print_board is not None:
        px_per_m = args.dpi / 0.0254
        image = spec.image(px_per_m, margin_px=round(spec.square_m * px_per_m))
        args.print_board.parent.mkdir(parents=True, exist_ok=True)
        if not cv2.imwrite(str(args.print_board), image):
            raise store.CalibrationError(f"cannot write {args.print_board}")
        w, h = spec.size_m
        print(
            f"wrote {args.print_board}: {spec.squares[0]}x{spec.squares[1]} squares of "
            f"{spec.square_m * 1000:g} mm ({w * 1000:g} x {h * 1000:g} mm) at {args.dpi:g} dpi; "
            "print at 100% and measure a square"
        )
        if args.images is None and args.camera is None:
            return 0
    if args.images is not None:
        views, size, missed = charuco.views_from_folder(args.images, spec)
        if missed:
            print(f"board not found in {len(missed)} image(s): {', '.join(missed[:10])}")
    elif args.camera is not None:
        views, size = _live_views(args, spec)
    else:
        raise store.CalibrationError("give --images FOLDER or --camera SOURCE (or --print-board)")
    result = charuco.calibrate(views, size, fit_k3=args.fit_k3, board=spec)
    path = store.save("camera", args.rig_id, result.to_dict(spec), args.dir)
    print(f"camera: {result.describe()}")
    print(f"distortion (k1, k2, p1, p2, k3): {', '.join(f'{d:+.4f}' for d in result.dist_coeffs)}")
    print("per view, RMS px fitted / held out: " + ", ".join(
        f"{name or i} {a:.2f}/{b:.2f}"
        for i, (name, a, b) in enumerate(
            zip(result.view_names, result.per_view_rms_px, result.held_out_per_view_px, strict=True)
        )
    ))  # fmt: skip
    if result.rms_px > charuco.GOOD_RMS_PX:
        print(
            f"warning: RMS above {charuco.GOOD_RMS_PX} px: check focus, motion blur and the "
            "board's flatness"
        )
    print(
        f"accepted: every intrinsic known to within {charuco.MAX_SD_OF_FOCAL:.1%} of the focal "
        "length (1 sd)" + (", and for a better calibration:" if result.advice else "")
    )
    for item in result.advice:
        print(f"advice: {item}")
    print(f"saved {path}")
    return 0


def _live_views(args: argparse.Namespace, spec) -> tuple[list, tuple[int, int]]:
    import numpy as np

    from vision.camera import EndOfStream
    from vision.make_camera import make_camera

    views: list = []
    size = (0, 0)
    last = None
    print(f"show the board at {args.views} places and tilts; Ctrl-C to stop early")
    with make_camera(args.camera) as cam:
        for n in range(args.max_frames):
            if len(views) >= args.views:
                break
            try:
                image = cam.read().image
            except EndOfStream:  # a recorded video: use what it had
                break
            size = (image.shape[1], image.shape[0])
            view = spec.detect(image, f"frame{n}")
            if view is None:
                continue
            centre = view.image_points.mean(axis=0)
            if last is not None and np.linalg.norm(centre - last) < MIN_VIEW_SHIFT_PX:
                continue
            last = centre
            views.append(view)
            print(f"view {len(views)}/{args.views}: {len(view.image_points)} corners")
    return views, size


# ---- arena -------------------------------------------------------------------------------
def _read_frame(args: argparse.Namespace):
    import cv2

    from calibration.store import CalibrationError

    if args.image is not None:
        image = cv2.imread(str(args.image), cv2.IMREAD_COLOR)
        if image is None:
            raise CalibrationError(f"cannot read image {args.image}")
        return image
    from vision.make_camera import make_camera

    with make_camera(args.camera) as cam:
        for _ in range(5):  # let auto-exposure settle on a live camera (guess: 5 frames)
            image = cam.read().image
    return image


def _intrinsics(args: argparse.Namespace, size: tuple[int, int]):
    import numpy as np

    from calibration import store

    try:
        data = store.load("camera", args.rig_id, args.dir)
    except store.CalibrationError as exc:
        if args.fovy is None:
            raise store.CalibrationError(
                f"{exc}: run `ergo calibrate camera --rig-id {args.rig_id}` first, or pass --fovy "
                "for an ideal pinhole camera"
            ) from None
        w, h = size
        f = (h / 2.0) / math.tan(math.radians(args.fovy) / 2.0)
        k = np.array([[f, 0.0, (w - 1) / 2.0], [0.0, f, (h - 1) / 2.0], [0.0, 0.0, 1.0]])
        return k, np.zeros(5), f"ideal pinhole, fovy {args.fovy:g} deg"
    if tuple(data["image_size"]) != tuple(size):
        raise store.CalibrationError(
            f"the camera was calibrated at {data['image_size'][0]}x{data['image_size'][1]}, "
            f"this frame is {size[0]}x{size[1]}: recalibrate or use the same resolution"
        )
    return (
        np.asarray(data["camera_matrix"], float),
        np.asarray(data["dist_coeffs"], float),
        "camera calibration",
    )


def _marker_layout(args: argparse.Namespace):
    from calibration import arena as ar

    return ar.MarkerLayout(
        markers=ar.parse_markers(args.markers) if args.markers else dict(ar.DEFAULT_MARKERS),
        size_m=args.marker_size or ar.DEFAULT_MARKER_SIZE_M,
        dictionary=args.dictionary,
    )


def _print_markers(args: argparse.Namespace) -> None:
    import cv2

    from calibration import arena as ar
    from calibration.store import CalibrationError

    layout = _marker_layout(args)
    radius = args.radius if args.radius is not None else ar.DEFAULT_RADIUS_M
    page = ar.marker_sheet(layout, args.dpi, radius)
    args.print_markers.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(args.print_markers), page):
        raise CalibrationError(f"cannot write {args.print_markers}")
    where = ", ".join(
        f"id {i} at ({x * 1000:+.0f}, {y * 1000:+.0f}) mm"
        for i, (x, y) in sorted(layout.markers.items())
    )
    print(
        f"wrote {args.print_markers}: {len(layout.markers)} {layout.dictionary} markers of "
        f"{layout.size_m * 1000:g} mm on A4 at {args.dpi:g} dpi; print at 100% and check the "
        f"50 mm bar; lay them flat on the floor, printed top edge towards +y (the top of the "
        f"camera image), centres at: {where} (x to the image's right, origin at the arm's base)"
    )


@_command
def _arena(args: argparse.Namespace) -> int:
    import numpy as np

    from calibration import arena as ar
    from calibration import ball_colour, store

    if args.print_markers is not None:
        _print_markers(args)
        if args.image is None and args.camera is None:
            return 0
    elif args.image is None and args.camera is None:
        raise store.CalibrationError(
            "give --image FRAME or --camera SOURCE (or --print-markers OUT.png)"
        )
    image = _read_frame(args)
    size = (image.shape[1], image.shape[0])
    k, dist, k_source = _intrinsics(args, size)
    centre = _pair(args.centre, "--centre")
    radius = args.radius if args.radius is not None else ar.DEFAULT_RADIUS_M
    layout = None
    if args.corners:
        if not args.corner_xy:
            raise store.CalibrationError("--corners needs --corner-xy (their arena positions)")
        px = np.array([_pair(c, "--corners") for c in args.corners])
        xy = np.array([_pair(c, "--corner-xy") for c in args.corner_xy.replace(";", " ").split()])
        if len(xy) != len(px):
            raise store.CalibrationError(
                f"--corner-xy has {len(xy)} positions for {len(px)} --corners pixels"
            )
        fit = ar.arena_from_points(px, xy, k, dist, size, centre, radius)
        source = "clicked points"
    else:
        layout = _marker_layout(args)
        fit = ar.arena_from_markers(image, layout, k, dist, centre, radius)
        source = f"{len(layout.markers)} ArUco markers"
    ranges = None
    if not args.no_ball:
        if args.ball_pixel:
            pixel = _pair(args.ball_pixel, "--ball-pixel")
        else:
            pixel = ball_colour.find_saturated_blob(image, fit.model, args.ball_radius)
        ranges = ball_colour.sample_ball_hsv(image, pixel)
        xy = ar.ball_position_check(fit.model, pixel, args.ball_radius)
        print(
            f"ball at pixel ({pixel[0]:.0f}, {pixel[1]:.0f}) -> arena ({xy[0] * 1000:+.1f}, "
            f"{xy[1] * 1000:+.1f}) mm; colour ranges "
            + " + ".join(f"{r.lower}-{r.upper}" for r in ranges)
        )
    payload = ar.arena_payload(fit, ranges, args.ball_radius, f"{source}; {k_source}", layout)
    path = store.save("arena", args.rig_id, payload, args.dir)
    pos = fit.model.camera_position
    height = f"camera {pos[2] * 1000:.0f} mm above the floor" if pos is not None else ""
    print(
        f"arena from {source} ({fit.points_used} points): residual max "
        f"{fit.residuals_mm.max():.2f} mm; {height}"
    )
    print(f"saved {path}")
    return 0


# ---- joints ------------------------------------------------------------------------------
def _make_arm(args: argparse.Namespace):
    """The arm the bus flags name, with raw servo angles (directions +1 and offsets 0, the
    backends' defaults), so that the result applies directly."""
    bus = bus_from_args(args)
    assert bus is not None  # argparse requires --port or --can
    return make_arm(bus, model=args.model) if bus.kind == "dynamixel" else make_arm(bus)


@_command
def _joints(args: argparse.Namespace) -> int:
    from calibration import store
    from calibration.joints import calibrate_joints, interactive_prompt

    path = store.calibration_path("joints", args.rig_id, args.dir)
    kept = f"{path} unchanged" if path.exists() else f"no {path.name} written"
    arm = _make_arm(args)
    print("torque goes off: hold the arm. Move the joints as asked, then press Enter.")
    at = ["before the first step"]

    def prompt(step) -> None:
        at[0] = (
            "at the zero pose"
            if step.target == "zero"
            else f"at {step.joint}'s {step.target} limit"
        )
        interactive_prompt(step)

    try:
        with arm:
            result = calibrate_joints(
                arm, prompt, joints=args.joints, notify=lambda m: print(m, flush=True)
            )
    except EOFError:
        print()
        return error(
            f"stdin closed {at[0]}: the calibration needs a person pressing Enter; nothing "
            f"saved ({kept})"
        )
    except KeyboardInterrupt:
        print()
        print(f"ergo: interrupted {at[0]}: nothing saved ({kept})", file=sys.stderr)
        return 130
    path = store.save("joints", args.rig_id, result.to_dict(), args.dir)
    for i, name in enumerate(result.names):
        print(
            f"{name}: offset {math.degrees(result.offsets[i]):+.1f} deg, direction "
            f"{int(result.directions[i]):+d}, range {math.degrees(result.lower[i]):+.0f}.."
            f"{math.degrees(result.upper[i]):+.0f} deg"
        )
    print(f"saved {path}")
    return 0


# ---- show --------------------------------------------------------------------------------
@_command
def _dynamics(args: argparse.Namespace) -> int:
    from calibration.dynamics.command import run

    return run(args)


def _summary(kind: str, data: dict[str, Any]) -> str:
    if kind == "dynamics":
        from calibration.dynamics.command import describe

        return describe(data)
    if kind == "camera":
        k = data["camera_matrix"]
        sd = data.get("std_px") or {}
        pm = lambda name: f" +-{sd[name]:.1f}" if name in sd else ""  # noqa: E731
        return (
            f"{data['image_size'][0]}x{data['image_size'][1]}, {data['n_views']} views, RMS "
            f"{data['rms_px']:.3f} px, fx {k[0][0]:.1f}{pm('fx')} fy {k[1][1]:.1f}{pm('fy')} "
            f"cx {k[0][2]:.1f}{pm('cx')} cy {k[1][2]:.1f}{pm('cy')} px"
        )
    if kind == "arena":
        c = data["centre"]
        return (
            f"centre ({c[0]:+.3f}, {c[1]:+.3f}) m, radius {data['radius']:.3f} m, ball ranges "
            f"{data.get('ball_hsv_ranges')}"
        )
    joints = []
    for i, name in enumerate(data["names"]):
        lo, hi = math.degrees(data["lower"][i]), math.degrees(data["upper"][i])
        joints.append(
            f"{name} {math.degrees(data['offsets'][i]):+.1f} deg {int(data['directions'][i]):+d} "
            f"[{lo:+.0f}, {hi:+.0f}]"
        )
    return "offset, direction, range per joint: " + "; ".join(joints)


def _age(created: Any) -> str:
    """How long ago a calibration was made, in words ("3 h ago"), or "of unknown age"."""
    from datetime import UTC, datetime

    if created is None:
        return "of unknown age"
    seconds = (datetime.now(UTC) - created).total_seconds()
    for unit, size in (("days", 86400), ("h", 3600), ("min", 60)):
        if seconds >= size:
            return f"made {seconds / size:.0f} {unit} ago"
    return "made just now" if seconds >= -60 else "dated in the future (check the clock)"


@_command
def _show(args: argparse.Namespace) -> int:
    from calibration import store

    bad = 0
    for kind in store.KINDS:
        path = store.calibration_path(kind, args.rig_id, args.dir)
        if not path.exists():
            print(f"{kind}: none ({path})")
            continue
        try:
            doc = store.load_document(path, kind)
            data = store.load_arena_file(path) if kind == "arena" else doc["data"]
        except store.CalibrationError as exc:
            print(f"{kind}: INVALID: {exc}")
            bad += 1
            continue
        print(
            f"{kind}: {_summary(kind, data)} ({path}, {_age(store.created_at(doc))}, "
            f"sha256 {store.file_sha256(path)[:12]})"
        )
    return 1 if bad else 0
