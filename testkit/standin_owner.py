"""A scripted owner: follows docs/real_arm.md on a served stand-in rig, typing the guide's
``ergo`` commands as a person types them and using the stand-in's hands where a person uses
theirs (moving the limp joints to the marks ``ergo calibrate joints`` asks for, holding a
chessboard in front of the camera while ``ergo calibrate camera`` collects views).

Every step is a subprocess of the installed ``ergo`` (``python -m explore.cli``), with the
calibration folder in ``ERGO_CALIBRATION_DIR``: nothing here calls the calibration code
directly, and nothing here reads the stand-in's hidden parameters (``testkit.standin_truth`` is for
tests and experiment scripts, which compare what the steps recovered against them).

Used by ``tests/system/test_guide.py`` and ``experiments/rehearse_real_arm.py``::

    with ServedRig("dynamixel", seed=7, hidden=tmp / "h.json") as rig:
        owner = Owner(rig, rig_id="s7", calibration_dir=tmp / "cal", log=print)
        owner.scan()
        owner.calibrate_joints()
        owner.calibrate_camera()
        owner.calibrate_arena()
        owner.show()
        owner.explore(tmp / "run", episodes=20, seed=0)
"""

from __future__ import annotations

import contextlib
import math
import os
import re
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from queue import Empty, Queue
from typing import Any, Literal

import numpy as np

from robot.spec import ArmSpec, ergo_jr_spec
from sim.standin.hands import HandsError
from sim.standin.hands_client import HandsClient

ERGO = [sys.executable, "-m", "explore.cli"]
START_BOUND_S = 90.0  # against hangs (the server imports MuJoCo, draws its floor); not a target
STEP_BOUND_S = 900.0  # one guide step, s, against hangs
EPISODE_BOUND_S = 10.0  # one episode of an exploration over a bus, s (2.4-2.7 s measured)
# How far short of a joint's stop a person's hand leaves it (guess: one does not lean on a stop).
SHORT_OF_STOP_RAD = math.radians(0.5)
# The joints folded back before m2 is taken to its forward (upper) stop: with m3 straight the
# arm hits the floor first (the hands report "blocked by the floor", docs/standin.md).
FOLD_FOR_M2_UPPER = {"m3": -1.5}
# The chessboard the guide prints (`ergo calibrate camera --print-board`): 10 x 7 squares of
# 20 mm (9 x 6 inner corners), and the poses a person holds it at in front of the camera:
# 0.32-0.42 m above the floor (the camera is 0.50-0.60 m up), within 8 cm of the arena's
# centre, tilted up to 30 deg and turned up to 40 deg (guesses; OpenCV's tutorial asks for
# varied tilts and positions).
BOARD = {"kind": "chessboard", "squares": [10, 7], "square_m": 0.02}
BOARD_HEIGHT_M = (0.32, 0.42)
BOARD_SHIFT_M = 0.08
BOARD_TILT_DEG = 30.0
BOARD_TURN_DEG = 40.0
BOARD_HOLD_S = 0.4  # how long each pose is held (the stream serves ~15 frames/s)
# A pose is held only if the nominal camera at the Ergo Jr's resolution (the twin's as the
# software assumes it, not the stand-in's hidden one: what a person sees of where the camera
# looks) shows every inner corner
# of the board this far inside the frame's edges (a share of its width and height), and the
# board's centre this far from the last pose's (px): ``ergo calibrate camera`` keeps a view
# only when its corners moved 25 px (calibration/cli.py MIN_VIEW_SHIFT_PX). Guesses; without
# them 35 of 50 poses gave no view on stand-in 41 (the board cut by the frame's edge, or
# where the last view was); of 3000 poses drawn as before, the nominal camera shows 2.5 %
# whole, and every one of them is whole in stand-ins 41 and 42's cameras (which show 31 % and
# 6 % of all the poses whole).
BOARD_IN_VIEW_MARGIN = 0.02
BOARD_MIN_SHIFT_PX = 40.0
# A prompt of `ergo calibrate joints` (calibration/joints.py: interactive_prompt)
_PROMPT = re.compile(r"\[([^\]]+)\](?: \(try \d+\))? (Put|Move) (.*?), then press Enter: ")


class OwnerError(RuntimeError):
    """A guide step failed: what it printed, in one line."""


@dataclass
class Step:
    """What one guide command did: its words, exit code and output."""

    command: list[str]
    rc: int
    stdout: str
    stderr: str
    seconds: float

    def text(self) -> str:
        return f"$ ergo {' '.join(self.command)}  (rc {self.rc}, {self.seconds:.0f} s)"


class ServedRig:
    """``ergo twin serve --bus BUS [--stand-in SEED --hidden PATH] [flags]`` in a subprocess,
    entered once it has announced its lines (the stand-in's last, else the ``--rig-id``
    servos line, else the hands').

    Attributes (once entered): ``bus_kind``, ``where`` (the pty, or ``slcan:PTY`` for
    CANopen), ``camera_url`` (None with ``--no-camera``), ``hands_port``, ``lines`` (the
    announced lines by first word; the bus's under ``bus``), ``proc``.

    Args:
        bus: the bus to serve.
        seed: the stand-in's seed (None: the served twin, nominal or ``--rig-id``'s).
        hidden: with ``seed``, where the server writes the hidden parameters.
        flags: more flags of ``ergo twin serve``.
        env: the server's environment (default: this process's).
        log: the server's stderr goes to this file (default: a pipe, read if it fails to
            start).
    """

    def __init__(
        self,
        bus: Literal["dynamixel", "canopen"],
        seed: int | None,
        hidden: Path | None = None,
        flags: Sequence[str] = (),
        env: Mapping[str, str] | None = None,
        log: Path | None = None,
    ) -> None:
        self.bus_kind = bus
        self.seed = seed
        self.hidden = None if hidden is None else Path(hidden)
        self.flags = list(flags)
        self.env = dict(env or os.environ)
        self.log = None if log is None else Path(log)
        self.lines: dict[str, str] = {}
        self.proc: subprocess.Popen[str] | None = None
        self.camera_url: str | None = None
        if seed is not None:
            self.ready = "stand-in"
        else:
            self.ready = "servos" if "--rig-id" in self.flags else "hands"

    def __enter__(self) -> ServedRig:
        cmd = [*ERGO, "twin", "serve", "--bus", self.bus_kind]
        if self.seed is not None:
            cmd += ["--stand-in", str(self.seed)]
        if self.hidden is not None:
            cmd += ["--hidden", str(self.hidden)]
        cmd += self.flags
        env = {**self.env, "PYTHONUNBUFFERED": "1"}
        err = subprocess.PIPE if self.log is None else open(self.log, "w")
        try:
            self.proc = subprocess.Popen(
                cmd, env=env, stdout=subprocess.PIPE, stderr=err, text=True
            )
        finally:
            if self.log is not None:
                err.close()  # the server holds its own copy
        queue: Queue[str] = Queue()  # a thread reads: select() misses lines already buffered
        threading.Thread(
            target=lambda: [queue.put(x) for x in self.proc.stdout], daemon=True
        ).start()
        deadline = time.monotonic() + START_BOUND_S
        while self.ready not in self.lines and time.monotonic() < deadline:
            try:
                line = queue.get(timeout=1.0).strip()
            except Empty:
                if self.proc.poll() is not None:
                    break
                continue
            self.lines.setdefault("bus" if " bus " in line else line.split()[0], line)
        if self.ready not in self.lines:
            self.stop()
            raise OwnerError(f"ergo twin serve did not start: {self.lines} {self._stderr_tail()}")
        pty = self.lines["bus"].split()[-1]
        self.where = pty if self.bus_kind == "dynamixel" else f"slcan:{pty}"
        if "camera" in self.lines:
            self.camera_url = self.lines["camera"].split()[-1]
        self.hands_port = int(self.lines["hands"].rsplit(":", 1)[1])
        return self

    def _stderr_tail(self) -> str:
        """The end of the server's stderr (it has ended), for an error message."""
        if self.log is not None:
            return self.log.read_text(errors="replace")[-2000:] if self.log.exists() else ""
        if self.proc is None or self.proc.stderr is None or self.proc.poll() is None:
            return ""
        return self.proc.stderr.read()[-2000:]

    def bus_flags(self) -> list[str]:
        """The flags that name this rig's bus on any ``ergo`` command."""
        return ["--port", self.where] if self.bus_kind == "dynamixel" else ["--can", self.where]

    def stop(self) -> int | None:
        """SIGTERM, then the exit code (None if it had to be killed)."""
        if self.proc is None or self.proc.poll() is not None:
            return None if self.proc is None else self.proc.returncode
        self.proc.terminate()
        try:
            return self.proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait(timeout=10)
            return None

    def __exit__(self, *exc: object) -> None:
        self.stop()


def _reader(stream: Any, out: list[str], chunks: Queue[str] | None = None) -> None:
    """Read a pipe to its end, character batches appended to ``out`` (and queued)."""
    fd = stream.fileno()
    while True:
        data = os.read(fd, 4096)
        if not data:
            break
        text = data.decode(errors="replace")
        out.append(text)
        if chunks is not None:
            chunks.put(text)


class Owner:
    """A person following the guide on a ``ServedRig``: each method is one step, runs the
    guide's command and returns its ``Step``; a failed step raises ``OwnerError`` with the
    command's last line (``check=False`` returns it instead).

    Args:
        rig: the served stand-in.
        rig_id: the id given to ``--rig-id`` (the calibration files' folder).
        calibration_dir: the calibration root (``ERGO_CALIBRATION_DIR`` of every step).
        log: told each command and what it printed (default: nothing).
        rng_seed: the owner's own randomness (where the board is held).
        hand_speed: how fast the owner's hands turn a joint, rad/s (None: the careful person
            of ``sim.standin.hands.HAND_SPEED_RAD_S``; tests take a brisker one).
    """

    def __init__(
        self,
        rig: ServedRig,
        rig_id: str,
        calibration_dir: Path,
        log: Callable[[str], None] | None = None,
        rng_seed: int = 0,
        hand_speed: float | None = None,
    ) -> None:
        self.rig = rig
        self.hand_speed = hand_speed
        self.rig_id = rig_id
        self.calibration_dir = Path(calibration_dir)
        self.log = log or (lambda text: None)
        self.rng = np.random.default_rng(rng_seed)
        self.spec: ArmSpec = ergo_jr_spec()
        self.env = {**rig.env, "ERGO_CALIBRATION_DIR": str(self.calibration_dir)}
        self.steps: list[Step] = []
        self.stops: list[str] = []  # safety stops of explorations, resumed

    # ---- running a command -------------------------------------------------------------
    def _finish(self, step: Step, check: bool) -> Step:
        self.steps.append(step)
        self.log(step.text())
        self.log((step.stdout + step.stderr).rstrip())
        return self._finish_checked(step, check)

    def run(self, *args: str, check: bool = True, timeout: float = STEP_BOUND_S) -> Step:
        """``ergo ARGS`` with stdin closed."""
        t0 = time.monotonic()
        done = subprocess.run(
            [*ERGO, *args],
            env=self.env,
            stdin=subprocess.DEVNULL,
            capture_output=True,
            text=True,
            timeout=timeout,
        )
        step = Step(list(args), done.returncode, done.stdout, done.stderr, time.monotonic() - t0)
        return self._finish(step, check)

    def _run_with(
        self,
        args: Sequence[str],
        on_output: Callable[[str, subprocess.Popen[bytes]], None] | None,
        beside: Callable[[threading.Event], None] | None = None,
        check: bool = True,
        program: Sequence[str] = ERGO,
    ) -> Step:
        """``ergo ARGS`` (or ``program ARGS``) with a pipe on stdin: ``on_output(all output so
        far, process)`` is called on each new piece of stdout (it may answer on stdin);
        ``beside(stop)`` runs in a thread until the command ends (``stop`` is then set)."""
        t0 = time.monotonic()
        proc = subprocess.Popen(
            [*program, *args],
            env={**self.env, "PYTHONUNBUFFERED": "1"},
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
        )
        out: list[str] = []
        err: list[str] = []
        chunks: Queue[str] = Queue()
        threads = [
            threading.Thread(target=_reader, args=(proc.stdout, out, chunks), daemon=True),
            threading.Thread(target=_reader, args=(proc.stderr, err), daemon=True),
        ]
        stop = threading.Event()
        if beside is not None:
            threads.append(threading.Thread(target=beside, args=(stop,), daemon=True))
        for t in threads:
            t.start()
        try:
            while proc.poll() is None or not chunks.empty():
                if time.monotonic() - t0 > STEP_BOUND_S:
                    raise OwnerError(
                        f"ergo {' '.join(args[:2])} still running after {STEP_BOUND_S:.0f} s"
                    )
                try:
                    chunks.get(timeout=0.2)
                except Empty:
                    continue
                if on_output is not None and proc.poll() is None:
                    on_output("".join(out), proc)
        finally:
            stop.set()
            if proc.poll() is None:
                proc.kill()
            proc.wait(timeout=30)
            for t in threads:
                t.join(timeout=30)
        step = Step(list(args), proc.returncode, "".join(out), "".join(err), time.monotonic() - t0)
        return self._finish(step, check)

    def hands(self) -> HandsClient:
        return HandsClient(self.rig.hands_port)

    def torque_read_back(self) -> list[bool]:
        """Whether each servo (m1..m6) has its torque on, read over the bus by a reader of its
        own after a step has ended (not the arm that ran it): the XL-320's Torque Enable
        register, or the CiA 402 statusword (0x6041) by SDO, OPERATION ENABLED counting as on."""
        ids = self.spec.ids
        if self.rig.bus_kind == "dynamixel":
            from robot.dynamixel.bus import DynamixelBus

            with DynamixelBus(self.rig.where, latency_s=0.05, retries=5) as bus:
                return [bool(bus.read_register(i, "torque")) for i in ids]
        import canopen

        from robot.canopen.bus import parse_can_spec
        from robot.canopen.cia402 import State, decode_statusword

        network = canopen.Network()
        network.connect(**parse_can_spec(self.rig.where, None).bus_kwargs())
        try:
            on = []
            for i in ids:
                node = network.add_node(canopen.RemoteNode(i, canopen.ObjectDictionary()))
                node.sdo.RESPONSE_TIMEOUT = 2.0  # the emulator on a loaded machine
                word = int.from_bytes(node.sdo.upload(0x6041, 0), "little")
                on.append(decode_statusword(word) == State.OPERATION_ENABLED)
            return on
        finally:
            network.disconnect()

    # ---- the guide's steps -------------------------------------------------------------
    def scan(self, check: bool = True) -> Step:
        """``ergo bus scan``: which servos answer."""
        return self.run("bus", "scan", *self.rig.bus_flags(), check=check)

    def calibrate_joints(
        self,
        joints: Sequence[str] | None = None,
        check: bool = True,
        command: Sequence[str] | None = None,
    ) -> Step:
        """``ergo calibrate joints``: the hands put the limp arm at its zero marks, then each
        joint at its stops, pressing Enter after each move as the command asks; the arm is
        left held at its zero pose. ``command``: another command line that asks the same
        prompts (``lerobot-calibrate`` on the Ergo Jr's LeRobot plugin), run instead."""
        args = ["calibrate", "joints", "--rig-id", self.rig_id, *self.rig.bus_flags()]
        if joints:
            args += ["--joints", *joints]
        program = ERGO
        if command is not None:
            program, args = list(command[:1]), list(command[1:])
        answered = [0]
        failure: list[str] = []
        with self.hands() as hands:

            def answer(text: str, proc: subprocess.Popen[bytes]) -> None:
                prompts = _PROMPT.findall(text)
                if len(prompts) <= answered[0] or not text.endswith(": "):
                    return
                names, _verb, what = prompts[-1]
                try:
                    self._pose_for(hands, [n.strip() for n in names.split(",")], what)
                except HandsError as exc:
                    failure.append(str(exc))
                    proc.kill()
                    return
                answered[0] = len(prompts)
                with contextlib.suppress(BrokenPipeError):  # it ended meanwhile: its rc says
                    proc.stdin.write(b"\n")
                    proc.stdin.flush()

            step = self._run_with(args, answer, check=False, program=program)
            if failure:
                raise OwnerError(f"the hands could not do what the calibration asked: {failure[0]}")
            self._to_zero(hands)
        return self._finish_checked(step, check)

    def _finish_checked(self, step: Step, check: bool) -> Step:
        if check and step.rc != 0:
            last = (step.stderr.strip() or step.stdout.strip() or "no output").splitlines()[-1]
            raise OwnerError(f"ergo {step.command[0]} {step.command[1]} failed: {last}")
        return step

    def _to_zero(self, hands: HandsClient) -> None:
        """Back to the zero pose, m2 first (it may be forward with m3 folded back)."""
        hands.move({"m2": 0.0}, self.hand_speed)
        hands.move({name: 0.0 for name in self.spec.names}, self.hand_speed)

    def _pose_for(self, hands: HandsClient, names: list[str], what: str) -> None:
        """Move the joints as a prompt's words ask: "the arm in its zero pose", "m3 at its
        zero mark", "m3 to its lower limit ...", "m3 to its upper limit ..."."""
        self._to_zero(hands)
        if "zero" in what:
            return
        (name,) = names
        joint = self.spec.joints[self.spec.names.index(name)]
        if "lower limit" in what:
            target = joint.lower + SHORT_OF_STOP_RAD
        elif "upper limit" in what:
            target = joint.upper - SHORT_OF_STOP_RAD
        else:
            raise HandsError(f"cannot read the prompt {what!r}")
        if name == "m2" and target > 0:
            hands.move(FOLD_FOR_M2_UPPER, self.hand_speed)
        hands.move({name: target}, self.hand_speed)

    def board_poses(
        self, n: int
    ) -> list[tuple[tuple[float, float, float], tuple[float, float, float]]]:
        """``n`` poses (position m, euler deg) to hold the board at, drawn from the owner's
        randomness among those the nominal camera shows whole and apart from the pose before
        (``BOARD_IN_VIEW_MARGIN``, ``BOARD_MIN_SHIFT_PX``), as a person holding the board
        looks at the preview."""
        from sim.standin.board import BoardGeometry
        from sim.standin.hands import board_to_world
        from sim.standin.hidden import CAMERA_SIZE, nominal_camera

        camera = nominal_camera(CAMERA_SIZE)
        geometry = BoardGeometry.from_dict(BOARD)
        inner = geometry.object_corners()  # the corners the command must find, (N, 2) m
        (x0, y0), (x1, y1) = inner.min(axis=0), inner.max(axis=0)
        outline = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1], [(x0 + x1) / 2, (y0 + y1) / 2]])
        size = np.asarray(camera.size, float)
        low, high = BOARD_IN_VIEW_MARGIN * size, (1 - BOARD_IN_VIEW_MARGIN) * size
        poses: list[tuple[tuple[float, float, float], tuple[float, float, float]]] = []
        last = None
        for _ in range(1000 * n):
            if len(poses) == n:
                break
            x, y = self.rng.uniform(-BOARD_SHIFT_M, BOARD_SHIFT_M, 2)
            z = self.rng.uniform(*BOARD_HEIGHT_M)
            rx, ry = self.rng.uniform(-BOARD_TILT_DEG, BOARD_TILT_DEG, 2)
            rz = self.rng.uniform(-BOARD_TURN_DEG, BOARD_TURN_DEG)
            pose = ((float(x), float(y), float(z)), (float(rx), float(ry), float(rz)))
            px = camera.project(board_to_world(geometry, *pose, outline))
            inside = bool(np.all((px[:4] >= low) & (px[:4] <= high)))
            if not inside or (last is not None and np.hypot(*(px[4] - last)) < BOARD_MIN_SHIFT_PX):
                continue
            poses.append(pose)
            last = px[4]
        return poses

    def calibrate_camera(self, views: int = 15, check: bool = True) -> Step:
        """``ergo calibrate camera --camera URL --board chessboard``: the hands hold the board
        at a new pose every ``BOARD_HOLD_S`` until the command has its views, then put it
        away."""
        args = ["calibrate", "camera", "--rig-id", self.rig_id, "--camera", self.rig.camera_url]
        args += ["--board", "chessboard", "--squares", *map(str, BOARD["squares"])]
        args += ["--square-m", str(BOARD["square_m"]), "--views", str(views)]

        def hold(stop: threading.Event) -> None:
            with self.hands() as hands:
                while not stop.is_set():
                    for position, euler in self.board_poses(10):
                        if stop.is_set():
                            break
                        hands.show_board(BOARD, position, euler)
                        stop.wait(BOARD_HOLD_S)
                hands.put_board_away()

        return self._run_with(args, None, beside=hold, check=check)

    def calibrate_arena(self, check: bool = True) -> Step:
        """``ergo calibrate arena --camera URL``: the arena's four markers and the ball."""
        with self.hands() as hands:
            hands.put_board_away()
        return self.run(
            "calibrate", "arena", "--rig-id", self.rig_id, "--camera", self.rig.camera_url,
            check=check,
        )  # fmt: skip

    def show(self, check: bool = True) -> Step:
        """``ergo calibrate show``: the three files, their age and hash."""
        return self.run("calibrate", "show", "--rig-id", self.rig_id, check=check)

    def explore(
        self,
        out: Path,
        episodes: int,
        seed: int,
        strategy: str = "rge-efr",
        extra: Sequence[str] = (),
        check: bool = True,
        resumes: int = 0,
    ) -> Step:
        """``ergo explore --rig BUS --rig-id ID ... --camera URL``: the hands let go as the
        torque comes on. A run paused by a safety stop (its last line says ``resume with
        ergo explore --resume OUT``) is resumed as the guide says, up to ``resumes`` times;
        ``self.stops`` keeps each stop's line."""
        rig = "dynamixel" if self.rig.bus_kind == "dynamixel" else "canopen"
        bound = max(STEP_BOUND_S, EPISODE_BOUND_S * episodes)
        step = self.run(
            "explore", "--rig", rig, "--rig-id", self.rig_id, *self.rig.bus_flags(),
            "--camera", self.rig.camera_url, "--strategy", strategy,
            "--episodes", str(episodes), "--seed", str(seed), "--out", str(out), *extra,
            check=False, timeout=bound,
        )  # fmt: skip
        while step.rc != 0 and "ergo explore --resume" in step.stderr and resumes > 0:
            self.stops.append(step.stderr.strip().splitlines()[-1])
            resumes -= 1
            step = self.run("explore", "--resume", str(out), check=False, timeout=bound)
        return self._finish_checked(step, check)

    def kill_explore(
        self,
        out: Path,
        episodes: int,
        after: int,
        seed: int = 0,
        strategy: str = "rge-efr",
        extra: Sequence[str] = (),
    ) -> Step:
        """``ergo explore`` as in ``explore``, SIGKILLed (``kill -9 PID``: no handler runs)
        once ``after`` of its episodes are stored; its ``Step`` (rc -9). Resume it with
        ``ergo explore --resume OUT`` (``run``)."""
        import signal

        from explore.runs.store import RunStoreError, read_history

        rig = "dynamixel" if self.rig.bus_kind == "dynamixel" else "canopen"
        args = [
            "explore", "--rig", rig, "--rig-id", self.rig_id, *self.rig.bus_flags(),
            "--camera", self.rig.camera_url, "--strategy", strategy, "--episodes", str(episodes),
            "--seed", str(seed), "--out", str(out), "--no-progress", *extra,
        ]  # fmt: skip
        t0 = time.monotonic()
        proc = subprocess.Popen(
            [*ERGO, *args], env=self.env, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
            stderr=subprocess.PIPE, text=True,
        )  # fmt: skip
        stored = 0
        while proc.poll() is None and stored < after:
            if time.monotonic() - t0 > max(STEP_BOUND_S, EPISODE_BOUND_S * episodes):
                proc.kill()
                raise OwnerError(f"ergo explore stored {stored} of {after} episodes in time")
            time.sleep(0.2)
            with contextlib.suppress(RunStoreError, FileNotFoundError):
                stored = len(read_history(out).records)
        if proc.poll() is None:
            proc.send_signal(signal.SIGKILL)
        stdout, stderr = proc.communicate(timeout=STEP_BOUND_S)
        step = Step(args, proc.returncode, stdout, stderr, time.monotonic() - t0)
        return self._finish(step, check=False)

    def interrupt_explore(self, out: Path, after_s: float, seed: int = 0) -> Step:
        """``ergo explore`` as in ``explore``, stopped with Ctrl-C (SIGINT) ``after_s`` wall
        seconds after it started, as a person stops a run."""
        import signal

        rig = "dynamixel" if self.rig.bus_kind == "dynamixel" else "canopen"
        args = ["explore", "--rig", rig, "--rig-id", self.rig_id, *self.rig.bus_flags()]
        args += ["--camera", self.rig.camera_url, "--episodes", "1000", "--seed", str(seed)]
        args += ["--out", str(out), "--no-progress"]
        t0 = time.monotonic()
        proc = subprocess.Popen(
            [*ERGO, *args], env=self.env, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
            stderr=subprocess.PIPE, text=True,
        )  # fmt: skip
        time.sleep(after_s)
        proc.send_signal(signal.SIGINT)
        stdout, stderr = proc.communicate(timeout=STEP_BOUND_S)
        step = Step(args, proc.returncode, stdout, stderr, time.monotonic() - t0)
        return self._finish(step, check=False)


def read_saved(calibration_dir: Path, rig_id: str, kind: str) -> dict[str, Any]:
    """The ``data`` of a calibration file the steps saved (plain JSON: what a test compares)."""
    import json

    path = Path(calibration_dir) / rig_id / f"{kind}.json"
    return json.loads(path.read_text())["data"]
