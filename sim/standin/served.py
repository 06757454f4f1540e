"""What ``ergo twin serve`` serves besides the bus: the served twin (nominal, or a stand-in
rig drawn from ``--stand-in SEED``), its camera and its hands. The bus servers
(``sim/dynamixel/server.py``, ``sim/canopen/server.py``) are the only modules outside this
package that import it (tests/sim/standin/test_secrecy.py checks it).

    $ ergo twin serve --bus dynamixel --stand-in 7
    dynamixel bus on /dev/pts/7
    camera on http://127.0.0.1:41234/stream.mjpg
    hands on 127.0.0.1:41235
    stand-in seed 7: hidden parameters in /tmp/ergo-standin-7-hidden.json (tests only)

    $ ergo twin serve --bus dynamixel --rig-id ergo1      # the twin with ergo1's fitted servos
    ...
    servos of rig ergo1: fitted, from ~/.config/.../ergo1/dynamics.json (delay 13.9 ms, kp ...)
"""

from __future__ import annotations

import argparse
import shutil
import signal
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from plumbing.cli_errors import error
from robot.spec import ergo_jr_spec
from sim.mjpeg_server import MjpegServer
from sim.models.make_scene import rgb_text
from sim.servo_model import ServoModel, fitted_servos
from sim.standin.hands import HOST, Hands, HandsServer
from sim.standin.hidden import (
    HiddenRig,
    StandinError,
    default_hidden_path,
    draw_hidden,
    nominal_rig,
    write_hidden,
)
from sim.standin.lens import RenderPlan, ServedFrames, render_plan
from sim.standin.scene import write_served_scene
from sim.twin import Twin

__all__ = [
    "ServedRig",
    "StandinError",
    "open_served_rig",
    "serve_until_interrupted",
    "served_twin",
]


@dataclass
class ServedRig:
    """The served twin and what the bus emulators need of its rig.

    Attributes:
        twin: the twin (the served scene: markers, board, hands' grips; the rig's servos).
        directions: +1/-1 per joint, shape (6,), for the bus emulators.
        offsets: servo angle at joint zero per joint, shape (6,), rad, for the bus emulators
            (``servo_angle = direction * joint_angle + offset``, ``robot.angles``).
        plan: how the served camera's frames are made.
        lines: what to print once serving (the stand-in's hidden file).
    """

    twin: Twin
    directions: np.ndarray
    offsets: np.ndarray
    #: the CANopen drives' angle at joint zero, shape (6,), rad (``offsets`` unless a stand-in
    #: drawn with ``--zero-marks anywhere``)
    can_offsets: np.ndarray
    plan: RenderPlan
    lines: list[str]


def open_served_rig(args: argparse.Namespace) -> ServedRig:
    """The rig ``ergo twin serve`` serves: the nominal twin, with ``args.rig_id`` the twin with
    that rig's fitted servos (its dynamics.json; the nominal ones without it, said in the
    rig's line), or with ``args.stand_in`` a stand-in rig whose hidden parameters are written
    to ``args.hidden`` (default: a file per seed in the temporary folder); its floor of colour
    ``args.floor_rgb`` ((r, g, b) in 0..1; None: the twin's blue).

    Raises:
        StandinError: a bad seed, an unwritable hidden file, a damaged dynamics.json,
            ``--rig-id`` with ``--stand-in``, or a colour out of 0..1 (one line).
    """
    seed = getattr(args, "stand_in", None)
    rig_id = getattr(args, "rig_id", None)
    if seed is not None and rig_id is not None:
        raise StandinError(
            "--rig-id and --stand-in: a stand-in rig has its own (hidden) servos; give one"
        )
    zero_marks = getattr(args, "zero_marks", None) or "horn"
    if seed is None and zero_marks != "horn":
        raise StandinError("--zero-marks: a stand-in's hidden mounting (give --stand-in SEED)")
    rig = nominal_rig() if seed is None else draw_hidden(seed, zero_marks)
    floor_rgb = getattr(args, "floor_rgb", None)
    if floor_rgb is not None:
        try:
            rgb_text(floor_rgb)
        except ValueError as exc:
            raise StandinError(f"--floor-rgb: {exc}") from None
    lines = []
    servos = None
    if seed is not None:
        path = getattr(args, "hidden", None) or default_hidden_path(seed)
        try:
            path = write_hidden(rig, path)
        except OSError as exc:
            raise StandinError(f"cannot write the hidden parameters to {path}: {exc}") from None
        lines.append(f"stand-in seed {seed}: hidden parameters in {path} (tests only)")
    elif rig_id is not None:
        servos, line = rig_servos(rig_id)
        lines.append(line)
    twin, plan = served_twin(rig, servos, floor_rgb)
    return ServedRig(twin, rig.directions.copy(), rig.offsets.copy(), rig.can_offsets, plan, lines)


def rig_servos(rig_id: str) -> tuple[ServoModel | None, str]:
    """Rig ``rig_id``'s fitted servos (None: the nominal ones, no dynamics.json) and the line
    that says which, for ``ergo twin serve --rig-id``; a damaged file is a ``StandinError``."""
    from robot.calibration_files import CalibrationError, RigCalibration

    try:
        calibration = RigCalibration.find(rig_id)
    except CalibrationError as exc:
        raise StandinError(f"--rig-id: {exc}") from None
    try:
        servos, path = fitted_servos(calibration)
    except CalibrationError as exc:
        raise StandinError(f"{exc} (a damaged twin calibration is not ignored)") from None
    if servos is None:
        return None, f"servos of rig {rig_id}: nominal (no dynamics calibration {path})"
    kp = servos.array("kp")
    return servos, (
        f"servos of rig {rig_id}: fitted, from {path} (delay {servos.delay_s * 1e3:.1f} ms, "
        f"kp {kp.min():.2f}-{kp.max():.2f} N.m/rad)"
    )


def served_twin(
    rig: HiddenRig,
    servos: ServoModel | None = None,
    floor_rgb: tuple[float, float, float] | None = None,
) -> tuple[Twin, RenderPlan]:
    """The twin of a served rig (its scene written to a temporary folder, compiled, removed)
    and how its camera's frames are made; its servos are a stand-in's hidden ones, else
    ``servos`` (None: the nominal ones); its floor and kerb of colour ``floor_rgb`` ((r, g, b)
    in 0..1; None: the twin's blue)."""
    plan = render_plan(rig.camera)
    folder = tempfile.mkdtemp(prefix="ergo-served-")
    try:
        scene = write_served_scene(folder, rig, plan, floor_rgb)
        twin = Twin(scene=scene, servos=servos if rig.seed is None else rig.servos)
    finally:
        shutil.rmtree(folder, ignore_errors=True)  # the model is compiled: files not needed
    return twin, plan


# Servo ids (Dynamixel) and node ids (CANopen) of the served arm's six joints: 1..6.
SERVED_IDS = tuple(ergo_jr_spec().ids)
# How long the start-up check keeps asking for every id to answer before it announces the bus
# all the same (with a warning naming the silent ones), s. Guess: a start-up at load 10 on 2
# cores answers within a few seconds.
READY_DEADLINE_S = 30.0


def wait_until_answering(unanswered: Callable[[], list[int]], bus: str) -> None:
    """Ask ``unanswered()`` (the ids among ``SERVED_IDS`` that did not answer one request each,
    through the bus's own port as a client would) until it returns none, or
    ``READY_DEADLINE_S`` passed (then one warning on stderr naming them)."""
    deadline = time.monotonic() + READY_DEADLINE_S
    silent = unanswered()
    while silent and time.monotonic() < deadline:
        silent = unanswered()
    if silent:
        print(
            f"ergo: warning: {bus} bus: ids {silent} did not answer within "
            f"{READY_DEADLINE_S:.0f} s of start-up",
            file=sys.stderr,
            flush=True,
        )


def serve_until_interrupted(
    rig: ServedRig,
    args: Any,
    announce: list[str],
    unanswered: Callable[[], list[int]] | None = None,
) -> int:
    """The tail of ``ergo twin serve`` for every bus: serve the camera (unless ``--no-camera``;
    ``--camera-port``) and the hands (``--hands-port``); once every id answers on the bus
    (``unanswered``, see ``wait_until_answering``: a client that pings the ids right after the
    bus's line gets every answer, as it would not while the camera starts), print
    ``announce`` (the bus's lines), the camera's and the hands' addresses and the rig's own
    lines (one each, flushed, for a parent process to read), then block until Ctrl-C or
    SIGTERM (both end it cleanly: exit code 0). Returns the exit code (2 when a port cannot
    be bound)."""
    frames = ServedFrames(rig.twin, rig.plan)
    hands = Hands(rig.twin, textures_changed=frames.textures_changed.set)
    camera = None
    hands_server = HandsServer(hands, port=int(getattr(args, "hands_port", 0) or 0))
    try:
        if not getattr(args, "no_camera", False):
            camera = MjpegServer(frames, port=int(getattr(args, "camera_port", 0) or 0))
            camera.start()
        hands_server.start()
    except OSError as exc:
        code = error(exc)
        hands_server.stop()
        if camera is not None:
            camera.stop()
        return code
    previous = None
    if threading.current_thread() is threading.main_thread():  # SIGTERM stops as Ctrl-C does
        previous = signal.signal(signal.SIGTERM, _interrupt)
    try:
        if unanswered is not None:
            wait_until_answering(unanswered, announce[0].split(" ", 1)[0])
        # every line once SIGTERM is handled: a parent that stops the server as soon as it
        # has read them gets the clean exit (code 0)
        for line in announce:
            print(line, flush=True)
        if camera is not None:
            print(f"camera on {camera.url}", flush=True)
        print(f"hands on {HOST}:{hands_server.port}", flush=True)
        for line in rig.lines:
            print(line, flush=True)
        while True:
            time.sleep(1.0)
    except KeyboardInterrupt:
        pass
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)
        hands_server.stop()
        if camera is not None:
            camera.stop()
    return 0


def _interrupt(signum: int, frame: object) -> None:
    raise KeyboardInterrupt
