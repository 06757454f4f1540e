"""A pair of hands for the served twin: they move limp joints and hold a calibration board in
front of the camera, so that a test drives the interactive procedures (``ergo calibrate
joints`` prompts, ``ergo calibrate camera`` live views) exactly as a person would.

``Hands`` acts on the twin:
- ``move``: each named joint is taken from where it is to the given angle at a hand's speed
  and held there, until ``release`` (or until its torque comes on: a person lets go of a
  servo that starts to drive). Only a joint whose torque is off can be moved; a powered one is
  refused in one line. The hand is a joint equality of the served scene
  (``sim.standin.scene``): physics, not a teleport, so a held arm still pushes the ball.
- ``show_board``: a ChArUco board or a plain chessboard (``sim.standin.board``), of the given
  geometry, held at a pose in the world (the centre of its printed face, and its rotation);
  ``put_board_away`` takes it out of sight.
- every answer says what the hands did.

``HandsServer`` serves them on 127.0.0.1 only, one JSON object per line each way
(docs/standin.md has the protocol); ``HandsClient`` is the client tests use::

    with HandsClient(port) as hands:
        hands.move({"m3": 0.5})        # m3 at 0.5 rad (its true joint angle), held
        hands.show_board({"kind": "chessboard", "squares": [10, 7], "square_m": 0.025},
                         position=(0.0, 0.0, 0.3), euler_deg=(15, 0, 0))
        hands.release()

Angles are the twin's true joint angles (rad), positions metres in the world frame (origin at
the arm's base, z up), rotations degrees.
"""

from __future__ import annotations

import json
import logging
import math
import socketserver
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from robot.spec import ERGO_JR_JOINTS
from sim.loopback import HOST, LISTEN_BACKLOG
from sim.models.make_scene import BALL_RADIUS, OUTER_RADIUS
from sim.standin.board import BoardError, BoardGeometry
from sim.standin.scene import (
    BOARD_AWAY,
    BOARD_BODY,
    BOARD_TEXTURE,
    BOARD_THICKNESS_M,
    hand_name,
)
from sim.twin import Twin

log = logging.getLogger(__name__)

# How fast a hand turns a joint: about 90 degrees in 1.5 s (guess for a careful person); a move
# may ask for another speed up to the quickest hand, 90 degrees in a quarter second (guess: a
# brisk flick, about half the XL-320's no-load 11.9 rad/s, ROBOTIS datasheet).
HAND_SPEED_RAD_S = 1.0
MAX_HAND_SPEED_RAD_S = 6.0
# A held joint counts as there within this (the hand's grip holds it within 0.01 deg under
# the arm's weight, tests/sim/standin/test_hands.py).
REACHED_RAD = math.radians(0.5)
STILL_RAD_S = 0.01  # ... and still: slower than this (a person waits for the arm to settle)
# Simulated time a move may take beyond its planned duration before it is reported stuck (a
# joint pushed into the floor, say), s.
SETTLE_S = 1.5
# Wall-clock bound on one move, whatever the simulation does (the twin might not be running), s.
MOVE_WALL_BOUND_S = 120.0
TICK_S = 0.01  # how often the hands update their grips, wall s
IDLE_S = 0.5  # how often idle hands look up (a move wakes them at once), wall s
MAX_LINE = 1 << 16  # bytes of one request line
# Where a person holds a board (guesses): within arm's reach of the desk arm's base, m (the
# arena is 0.2 m in radius, the served camera under 1 m above it); turned at most a full turn
# about each axis, degrees (any pose has such angles); squares of printable size, m (a 2 mm
# square is the finest a laser printer keeps sharp; 0.2 m, a sheet of A3 across two squares).
BOARD_REACH_M = 1.5
BOARD_TURN_DEG = 360.0
BOARD_SQUARE_M = (0.002, 0.2)


class HandsError(RuntimeError):
    """What the hands refused or could not do; the message is one line."""


@dataclass
class _Grip:
    """A hand on one joint: from ``start`` to ``goal`` (rad) from simulated time ``t0`` at
    ``speed`` rad/s."""

    start: float
    goal: float
    t0: float
    speed: float = HAND_SPEED_RAD_S

    def angle(self, now: float) -> float:
        travel = max(0.0, now - self.t0) * self.speed
        step = min(abs(self.goal - self.start), travel)
        return self.start + math.copysign(step, self.goal - self.start)

    def done_at(self) -> float:
        return self.t0 + abs(self.goal - self.start) / self.speed


def euler_matrix(euler_deg: Sequence[float]) -> np.ndarray:
    """Rotation of extrinsic turns about the world's x, then y, then z axes (degrees), shape
    (3, 3): ``Rz @ Ry @ Rx``."""
    rx, ry, rz = (math.radians(float(a)) for a in euler_deg)
    cx, sx, cy, sy, cz, sz = (math.cos(rx), math.sin(rx), math.cos(ry), math.sin(ry),
                              math.cos(rz), math.sin(rz))  # fmt: skip
    x = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    y = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    z = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return z @ y @ x


def board_to_world(
    geometry: BoardGeometry,
    position: Sequence[float],
    euler_deg: Sequence[float],
    points: np.ndarray,
) -> np.ndarray:
    """World positions of points on a held board's printed face.

    Args:
        geometry: the board.
        position: the centre of its printed face (the squares' centre), shape (3,), metres.
        euler_deg: its rotation (``euler_matrix``); at (0, 0, 0) it lies face up, its columns
            along +x and its first row towards +y (upright in the overhead camera).
        points: board coordinates, shape (N, 2), metres from the squares' top-left outer
            corner, x along the columns and y along the rows (``BoardGeometry``).

    Returns:
        shape (N, 3), metres.
    """
    w, h = geometry.squares_m
    p = np.asarray(points, np.float64).reshape(-1, 2)
    local = np.column_stack([p[:, 0] - w / 2, h / 2 - p[:, 1], np.zeros(len(p))])
    return np.asarray(position, np.float64) + local @ euler_matrix(euler_deg).T


class Hands:
    """The hands acting on the served twin (thread-safe; ``start`` runs their grips).

    Args:
        twin: a twin of a served scene (``sim.standin.scene``: the hands' equalities and the
            board body).
        textures_changed: called after the board's image was drawn into the model (the served
            camera then makes its render context again: ``sim.standin.lens.ServedFrames``).
    """

    def __init__(self, twin: Twin, textures_changed: Callable[[], None] | None = None) -> None:
        m = twin.model
        self.twin = twin
        self._textures_changed = textures_changed
        self._eq = np.array([m.equality(hand_name(j)).id for j in ERGO_JR_JOINTS])
        self._qpos = np.array([m.joint(j).qposadr[0] for j in ERGO_JR_JOINTS])
        self._dof = np.array([m.joint(j).dofadr[0] for j in ERGO_JR_JOINTS])
        self._range = np.array([m.joint(j).range for j in ERGO_JR_JOINTS])
        self._board_mocap = int(m.body(BOARD_BODY).mocapid[0])
        self._board_geom = m.geom(BOARD_BODY).id
        tex = m.texture(BOARD_TEXTURE)
        self._tex_adr = int(tex.adr[0])
        self._tex_shape = (int(tex.height[0]), int(tex.width[0]), int(tex.nchannel[0]))
        self._grips: dict[int, _Grip] = {}
        self._board: BoardGeometry | None = None  # the image in the texture
        self._held_board: dict[str, Any] | None = None  # what is held, for status
        self.notes: list[str] = []  # things the hands did on their own (let go of a joint)
        self._lock = threading.Lock()  # the grips and notes (under the twin's lock too)
        self._stop = threading.Event()
        self._wake = threading.Event()  # a grip was added
        self._thread: threading.Thread | None = None

    # ---- lifecycle -------------------------------------------------------------------------
    def start(self) -> None:
        if self._thread is None:
            self._stop.clear()
            self._thread = threading.Thread(target=self._run, name="hands", daemon=True)
            self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        self._wake.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None

    def __enter__(self) -> Hands:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _run(self) -> None:
        said = None
        while not self._stop.wait(TICK_S):
            if not self._grips:  # nothing held: sleep until a move (or stop) wakes the hands
                self._wake.wait(IDLE_S)
                self._wake.clear()
                continue
            try:
                self.tick()
            except Exception as exc:  # keep trying; say why once, not every tick
                if repr(exc) != said:
                    log.exception("hands: update failed")
                    said = repr(exc)

    def tick(self) -> None:
        """Move every grip along its way; let go of a joint whose torque came on."""
        if not self._grips:  # nothing held: leave the twin's lock to the bus and the physics
            return
        with self.twin.lock, self._lock:
            now = self.twin.time
            powered = self.twin.torque_mask()
            for j in list(self._grips):
                if powered[j]:
                    self._let_go(j)
                    self.notes.append(f"let go of {ERGO_JR_JOINTS[j]}: its torque came on")
                else:
                    self.twin.model.eq_data[self._eq[j], 0] = self._grips[j].angle(now)

    def _let_go(self, j: int) -> None:
        self.twin.data.eq_active[self._eq[j]] = 0
        del self._grips[j]

    # ---- joints ----------------------------------------------------------------------------
    def _joint_index(self, name: Any) -> int:
        if name not in ERGO_JR_JOINTS:
            raise HandsError(f"no joint {name!r}: the arm has {', '.join(ERGO_JR_JOINTS)}")
        return ERGO_JR_JOINTS.index(name)

    def move(self, joints: Mapping[str, float], speed: Any = HAND_SPEED_RAD_S) -> dict[str, Any]:
        """Move limp joints (name -> angle, rad) to their angles at ``speed`` (rad/s, up to
        ``MAX_HAND_SPEED_RAD_S``) and hold them there; returns once they are there (what was
        done, and where the joints are)."""
        if not isinstance(joints, Mapping) or not joints:
            raise HandsError('move needs "joints": an object of joint name -> angle (rad)')
        number = isinstance(speed, int | float) and not isinstance(speed, bool)
        if not number or not 0.0 < speed <= MAX_HAND_SPEED_RAD_S:
            raise HandsError(
                f"move: speed must be a number in (0, {MAX_HAND_SPEED_RAD_S:g}] rad/s, "
                f"got {speed!r}"
            )
        goals: dict[int, float] = {}
        for name, angle in joints.items():
            j = self._joint_index(name)
            ok = isinstance(angle, int | float) and not isinstance(angle, bool)
            if not ok or not math.isfinite(angle):
                raise HandsError(f"{name}: angle must be a number (rad), got {angle!r}")
            lo, hi = self._range[j]
            if not lo <= angle <= hi:
                raise HandsError(
                    f"{name}: {angle:.3f} rad is past its stop ({lo:.3f}..{hi:.3f} rad): a hand "
                    "cannot push a joint beyond it"
                )
            goals[j] = float(angle)
        with self.twin.lock, self._lock:
            powered = [ERGO_JR_JOINTS[j] for j in goals if self.twin.torque_mask()[j]]
            if powered:
                raise HandsError(
                    f"{', '.join(powered)} {'has' if len(powered) == 1 else 'have'} torque on: a "
                    "hand cannot move a powered joint (turn its torque off first)"
                )
            now = self.twin.time
            q = self.twin.data.qpos[self._qpos]
            for j, goal in goals.items():
                grip = self._grips.get(j)
                start = grip.angle(now) if grip is not None else float(q[j])
                self._grips[j] = _Grip(start, goal, now, float(speed))
                self.twin.model.eq_data[self._eq[j], 0] = start
                self.twin.data.eq_active[self._eq[j]] = 1
            self._wake.set()
            deadline = max(g.done_at() for j, g in self._grips.items() if j in goals) + SETTLE_S
        names = ", ".join(ERGO_JR_JOINTS[j] for j in goals)
        wall_deadline = time.monotonic() + MOVE_WALL_BOUND_S
        while True:
            with self.twin.lock, self._lock:
                now = self.twin.time
                q = self.twin.data.qpos[self._qpos]
                v = self.twin.data.qvel[self._dof]
                lost = [ERGO_JR_JOINTS[j] for j in goals if j not in self._grips]
                planned = all(self._grips[j].done_at() <= now for j in goals if j in self._grips)
                there = all(
                    abs(q[j] - goal) <= REACHED_RAD and abs(v[j]) <= STILL_RAD_S
                    for j, goal in goals.items()
                )
            if lost:
                raise HandsError(f"let go of {', '.join(lost)}: its torque came on during the move")
            if planned and there:
                break
            if now > deadline or time.monotonic() > wall_deadline:
                far = {ERGO_JR_JOINTS[j]: round(float(q[j]), 4) for j in goals}
                raise HandsError(
                    f"{names} did not reach {self._fmt(goals)} (they are at {far} rad): "
                    "blocked by the floor or the ball? (still held)"
                )
            time.sleep(TICK_S)
        return {
            "did": f"holding {self._fmt(goals)}",
            "held": self.held(),
            "positions": {ERGO_JR_JOINTS[j]: float(q[j]) for j in goals},
        }

    def release(self, joints: Sequence[str] | None = None) -> dict[str, Any]:
        """Let go of the named joints (None: all); a limp joint may then fall."""
        with self.twin.lock, self._lock:
            which = list(self._grips) if joints is None else [self._joint_index(n) for n in joints]
            freed = [ERGO_JR_JOINTS[j] for j in sorted(which) if j in self._grips]
            for j in which:
                if j in self._grips:
                    self._let_go(j)
        did = f"let go of {', '.join(freed)}" if freed else "held no joint to let go of"
        return {"did": did, "held": self.held()}

    def held(self) -> dict[str, float]:
        """Joint name -> the angle its hand takes it to, rad."""
        with self._lock:
            return {ERGO_JR_JOINTS[j]: g.goal for j, g in sorted(self._grips.items())}

    @staticmethod
    def _fmt(goals: Mapping[int, float]) -> str:
        return ", ".join(f"{ERGO_JR_JOINTS[j]} at {a:.3f} rad" for j, a in goals.items())

    # ---- the board -------------------------------------------------------------------------
    def show_board(
        self,
        board: Mapping[str, Any],
        position: Sequence[float],
        euler_deg: Sequence[float] = (0.0, 0.0, 0.0),
    ) -> dict[str, Any]:
        """Hold a board of geometry ``board`` (``BoardGeometry.from_dict``) with the centre of
        its printed face at ``position`` (m) turned by ``euler_deg`` (``board_to_world``)."""
        try:
            geometry = BoardGeometry.from_dict(board)
        except BoardError as exc:
            raise HandsError(str(exc)) from None
        pos = _vector(position, "position")
        euler = _vector(euler_deg, "euler_deg")
        if pos[2] <= 0.0:
            raise HandsError(f"board position z = {pos[2]} m: it must be above the floor")
        if np.any(np.abs(pos) > BOARD_REACH_M):
            raise HandsError(
                f"board position {pos.tolist()} m: a hand reaches {BOARD_REACH_M} m at most"
            )
        if np.any(np.abs(euler) > BOARD_TURN_DEG):
            raise HandsError(
                f"board euler_deg {euler.tolist()}: each angle within +-{BOARD_TURN_DEG:g} deg"
            )
        lo, hi = BOARD_SQUARE_M
        if not lo <= geometry.square_m <= hi:
            raise HandsError(f"board square_m {geometry.square_m}: must be in [{lo}, {hi}] m")
        rot = euler_matrix(euler)
        body = pos - rot[:, 2] * BOARD_THICKNESS_M / 2  # the box's centre behind its face
        import mujoco

        changed = False
        with self.twin.lock:
            m, d = self.twin.model, self.twin.data
            if geometry != self._board:
                n = np.prod(self._tex_shape)
                image = geometry.texture(self._tex_shape[0])[:, :, : self._tex_shape[2]]
                m.tex_data[self._tex_adr : self._tex_adr + n] = image.reshape(-1)
                w, h = geometry.size_m
                half = np.array([w / 2, h / 2, BOARD_THICKNESS_M / 2])
                m.geom_size[self._board_geom] = half
                m.geom_rbound[self._board_geom] = float(np.linalg.norm(half))
                m.geom_aabb[self._board_geom] = np.concatenate([np.zeros(3), half])
                self._board = geometry
                changed = True
            d.mocap_pos[self._board_mocap] = body
            quat = np.zeros(4)
            mujoco.mju_mat2Quat(quat, np.ascontiguousarray(rot).reshape(-1))
            d.mocap_quat[self._board_mocap] = quat
            mujoco.mj_kinematics(m, d)
            held = {
                "board": geometry.to_dict(),
                "position": pos.tolist(),
                "euler_deg": euler.tolist(),
            }
            self._held_board = held
        if changed and self._textures_changed is not None:
            self._textures_changed()
        x, y, z = pos
        rx, ry, rz = euler
        return {
            "did": (
                f"holding {geometry.describe()} at ({x:.3f}, {y:.3f}, {z:.3f}) m, turned "
                f"({rx:.1f}, {ry:.1f}, {rz:.1f}) deg"
            ),
            **held,
        }

    def put_board_away(self) -> dict[str, Any]:
        """Take the board out of sight (below the floor)."""
        import mujoco

        with self.twin.lock:
            self.twin.data.mocap_pos[self._board_mocap] = BOARD_AWAY
            self.twin.data.mocap_quat[self._board_mocap] = (1.0, 0.0, 0.0, 0.0)
            mujoco.mj_kinematics(self.twin.model, self.twin.data)
            was = self._held_board is not None
            self._held_board = None
        return {"did": "put the board away" if was else "held no board"}

    # ---- the ball ----------------------------------------------------------------------------
    def place_ball(self, position: Any) -> dict[str, Any]:
        """Put the ball down at rest with its centre above ``position`` (x, y) m, inside the
        wall (its centre at most the wall's radius less its own from the centre)."""
        try:
            xy = np.asarray(position, dtype=float).reshape(-1)
        except (TypeError, ValueError):
            xy = np.zeros(0)
        if xy.shape != (2,) or not np.all(np.isfinite(xy)):
            raise HandsError(
                f"ball: position must be two finite numbers (x, y) m, got {position!r}"
            )
        limit = OUTER_RADIUS - BALL_RADIUS
        if float(np.hypot(*xy)) > limit + 1e-9:
            raise HandsError(
                f"ball: ({xy[0]:.3f}, {xy[1]:.3f}) m is outside the wall (the ball's centre "
                f"lies within {limit:.2f} m of the arm's base)"
            )
        self.twin.place_ball((float(xy[0]), float(xy[1])))
        return {"did": f"put the ball at ({xy[0]:+.3f}, {xy[1]:+.3f}) m", "position": xy.tolist()}

    # ---- the protocol ----------------------------------------------------------------------
    def status(self) -> dict[str, Any]:
        """What the hands hold now (their grips brought up to date first), and the notes of
        what they did on their own since the last status."""
        self.tick()
        with self._lock:
            notes, self.notes = self.notes, []
        return {"did": "nothing", "held": self.held(), "board": self._held_board, "notes": notes}

    def handle(self, request: Any) -> dict[str, Any]:
        """Answer one request object (docs/standin.md): ``{"ok": true, "did": ...}`` or
        ``{"ok": false, "error": "one line"}``."""
        try:
            if not isinstance(request, Mapping):
                raise HandsError(f"a request is a JSON object, got {type(request).__name__}")
            cmd = request.get("cmd")
            fields = {k: v for k, v in request.items() if k != "cmd"}
            allowed = {
                "move": {"joints", "speed"},
                "release": {"joints"},
                "board": {"board", "position", "euler_deg"},
                "board_away": set(),
                "ball": {"position"},
                "status": set(),
            }
            if cmd not in allowed:
                raise HandsError(f"unknown cmd {cmd!r}: expected one of {', '.join(allowed)}")
            extra = sorted(set(fields) - allowed[cmd])
            if extra:
                raise HandsError(f"{cmd}: unknown field(s) {', '.join(extra)}")
            if cmd == "move":
                reply = self.move(fields.get("joints"), fields.get("speed", HAND_SPEED_RAD_S))
            elif cmd == "release":
                joints = fields.get("joints")
                if joints is not None and not isinstance(joints, list):
                    raise HandsError('release: "joints" must be a list of joint names')
                reply = self.release(joints)
            elif cmd == "board":
                if "board" not in fields or "position" not in fields:
                    raise HandsError('board needs "board" (its geometry) and "position" (m)')
                reply = self.show_board(
                    fields["board"], fields["position"], fields.get("euler_deg", (0, 0, 0))
                )
            elif cmd == "board_away":
                reply = self.put_board_away()
            elif cmd == "ball":
                reply = self.place_ball(fields.get("position"))
            else:
                reply = self.status()
        except HandsError as exc:
            return {"ok": False, "error": str(exc)}
        return {"ok": True, **reply}


def _vector(value: Any, name: str) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise HandsError(f"{name} must be three numbers, got {value!r}") from None
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise HandsError(f"{name} must be three finite numbers, got {value!r}")
    return arr


class HandsServer:
    """Serves ``Hands`` on 127.0.0.1: one JSON request per line, one JSON reply per line.

    Args:
        hands: who acts.
        port: TCP port (0: any free port; see ``port`` after ``start``).
    """

    def __init__(self, hands: Hands, port: int = 0) -> None:
        self.hands = hands
        self._requested_port = port
        self._server: socketserver.ThreadingTCPServer | None = None
        self._thread: threading.Thread | None = None

    @property
    def port(self) -> int:
        if self._server is None:
            raise RuntimeError("hands server not started")
        return int(self._server.server_address[1])

    def start(self) -> None:
        if self._server is not None:
            return
        hands = self.hands

        class Handler(socketserver.StreamRequestHandler):
            def handle(self) -> None:
                while True:
                    try:
                        line = self.rfile.readline(MAX_LINE + 1)
                    except OSError:
                        return
                    if not line:
                        return
                    if len(line) > MAX_LINE:
                        reply = {"ok": False, "error": f"request longer than {MAX_LINE} bytes"}
                    else:
                        try:
                            request = json.loads(line)
                        except ValueError as exc:
                            reply = {"ok": False, "error": f"not JSON: {exc}"}
                        else:
                            reply = hands.handle(request)
                    try:
                        self.wfile.write((json.dumps(reply) + "\n").encode())
                        self.wfile.flush()
                    except OSError:
                        return

        class Server(socketserver.ThreadingTCPServer):
            daemon_threads = True
            allow_reuse_address = True
            request_queue_size = LISTEN_BACKLOG  # socketserver's 5 dropped connections

        try:
            self._server = Server((HOST, self._requested_port), Handler)
        except OSError as exc:
            raise OSError(
                f"cannot serve the hands on {HOST}:{self._requested_port}: {exc}"
            ) from exc
        self.hands.start()
        self._thread = threading.Thread(
            target=self._server.serve_forever, kwargs={"poll_interval": 0.1}, daemon=True
        )
        self._thread.start()

    def stop(self) -> None:
        if self._server is not None:
            self._server.shutdown()
            self._server.server_close()
            self._server = None
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
        self.hands.stop()

    def __enter__(self) -> HandsServer:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()
