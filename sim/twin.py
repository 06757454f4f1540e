"""The MuJoCo twin of the rig: the Ergo Jr, the arena, the ball and the overhead camera.

``Twin`` is plain physics with named queries (dm_control style); robots and cameras wrap it
(``SimArm``, ``SimCamera``) and bus emulators serve it over a wire protocol. A ``threading.RLock``
(``Twin.lock``) guards it for emulators that read and step from several threads.

Units: metres, radians, seconds. Images are BGR uint8 (OpenCV order).
"""

from __future__ import annotations

import contextlib
import math
import os
import threading
from collections import deque
from pathlib import Path
from typing import Protocol

from plumbing.fixed_order import norm
from robot.spec import ERGO_JR_JOINTS
from sim.headless import ensure_fork_safe_software_gl, ensure_headless_gl
from sim.servo_model import ServoModel, read_model, write_model

ensure_headless_gl()
ensure_fork_safe_software_gl()

import mujoco  # noqa: E402
import numpy as np  # noqa: E402

MODELS = Path(__file__).parent / "models"
SCENE = MODELS / "scene.xml"
SCENE_DISTRACTOR = MODELS / "scene_distractor.xml"  # the same with a second ball (make_scene.py)
JOINTS = ERGO_JR_JOINTS  # the MJCF's joint and actuator names (sim/models/ergo_jr.xml)


# Renderers a forked child inherited from its parent: their GL contexts belong to the parent's
# driver state, so the child never draws with, frees or garbage-collects them (freeing one
# calls into the driver, which can block in a child). Kept referenced until the child exits.
_INHERITED_RENDERERS: list[mujoco.Renderer] = []


class Pacer(Protocol):
    """What keeps a twin's simulated time at wall time (``sim.realtime.RealtimeLoop``)."""

    def catch_up(self, request: bool = True) -> float:
        """Step the twin up to the current wall time; returns how far behind it was, s."""
        ...

    def target_time(self, wall: float | None = None) -> float:
        """The simulated time at wall time ``wall`` (default now), s."""
        ...

    def restart(self) -> None:
        """The twin's time was set back (a reset, a restored state): follow wall time from it."""
        ...


def _as_slice(index: np.ndarray) -> slice | np.ndarray:
    """``index`` (ascending ints) as a slice where it is a contiguous run, else itself."""
    first = int(index[0])
    if np.array_equal(index, np.arange(first, first + len(index))):
        return slice(first, first + len(index))
    return index


def _take(values: np.ndarray, where: slice | np.ndarray) -> np.ndarray:
    """``values[where]`` as a new array (a slice's view copied; an index array gathers)."""
    return values[where].copy() if isinstance(where, slice) else values[where]


class TwinError(RuntimeError):
    """The twin's model could not be loaded or its state restored."""


class Twin:
    """MuJoCo model and data of the arena scene.

    Args:
        scene: MJCF file to load (default: ``sim/models/scene.xml``).
        render_size: (height, width) of overhead renders, pixels.
        servos: the servos' dynamics (``sim.servo_model.ServoModel``; default: the scene's
            own, ``sim.servo_model.NOMINAL`` for the committed scenes). A model with a
            ``delay_s`` holds each command that long before the actuators see it.
    """

    def __init__(
        self,
        scene: str | Path = SCENE,
        render_size: tuple[int, int] = (240, 240),
        servos: ServoModel | None = None,
    ) -> None:
        try:
            self.model = mujoco.MjModel.from_xml_path(str(scene))
        except (ValueError, FileNotFoundError) as exc:
            raise TwinError(f"cannot load twin scene {scene}: {exc}") from exc
        self.data = mujoco.MjData(self.model)
        self._timestep = float(self.model.opt.timestep)
        self.lock = threading.RLock()
        # Who keeps simulated time at wall time (a sim.realtime.RealtimeLoop sets itself here
        # while it runs; None: whoever calls ``step`` decides the time): ``catch_up`` asks it.
        self.pacer: Pacer | None = None
        m = self.model
        self._qpos_idx = np.array([m.joint(j).qposadr[0] for j in JOINTS])
        self._qvel_idx = np.array([m.joint(j).dofadr[0] for j in JOINTS])
        self._act_idx = np.array([m.actuator(j).id for j in JOINTS])
        # the same as slices where the six are contiguous (the scene's order): a slice and a
        # copy cost a third of an index array's gather (the joint queries, every control tick)
        self._reading = tuple(_as_slice(i) for i in (self._qpos_idx, self._qvel_idx, self._act_idx))
        ball = m.joint("ball")
        self._ball_qpos = int(ball.qposadr[0])
        self._ball_qvel = int(ball.dofadr[0])
        self.ball_radius = float(m.geom("ball").size[0])
        # the distractor's mocap index, or None when the scene has none
        ids = [i for i in range(m.nbody) if m.body(i).name == "distractor"]
        self._distractor = int(m.body(ids[0]).mocapid[0]) if ids else None
        self._tip_site = m.site("tip").id
        if servos is not None:
            write_model(self.model, self._act_idx, self._qvel_idx, servos)
        self.servos = read_model(self.model, self._act_idx, self._qvel_idx).replace(
            delay_s=servos.delay_s if servos is not None else 0.0
        )
        self._kp = self.model.actuator_gainprm[self._act_idx, 0].copy()
        self._bias = self.model.actuator_biasprm[self._act_idx, :3].copy()
        # Commands not yet seen by the actuators (a servo model with a transport delay):
        # (simulated time they arrive, s; targets, shape (6,), rad), oldest first.
        self._pending: deque[tuple[float, np.ndarray]] = deque()
        self._renderers: dict[tuple[int, int], mujoco.Renderer] = {}
        self._renderers_pid = os.getpid()  # the process whose GL contexts they are
        self.render_size = render_size
        self.reset()

    # ---- state -----------------------------------------------------------------------------
    @property
    def timestep(self) -> float:
        """Physics step, s (the model's, read once: ``model.opt`` builds a new view per access,
        and ``step`` needs it every control tick)."""
        return self._timestep

    @property
    def time(self) -> float:
        """Simulated time since reset, s."""
        return float(self.data.time)

    def reset(self, ball_xy: tuple[float, float] | None = None) -> None:
        """Back to the ``home`` keyframe (arm at rest); ball placed at ``ball_xy`` (m) if given."""
        with self.lock:
            self.set_torque(True)
            self._pending.clear()
            mujoco.mj_resetDataKeyframe(self.model, self.data, self.model.key("home").id)
            if ball_xy is not None:
                self.data.qpos[self._ball_qpos : self._ball_qpos + 2] = ball_xy
            mujoco.mj_forward(self.model, self.data)
            if self.pacer is not None:
                self.pacer.restart()

    def place_ball(self, ball_xy: tuple[float, float] | None = None) -> None:
        """Put the ball at rest at ``ball_xy`` (m; default: its ``home`` keyframe position),
        leaving the arm as it is."""
        with self.lock:
            home = self.model.key("home").qpos
            q = self._ball_qpos
            self.data.qpos[q : q + 7] = home[q : q + 7]
            if ball_xy is not None:
                self.data.qpos[q : q + 2] = ball_xy
            self.data.qvel[self._ball_qvel : self._ball_qvel + 6] = 0.0
            mujoco.mj_forward(self.model, self.data)

    def distractor_position(self) -> np.ndarray:
        """Distractor centre, shape (3,), m; NaN when the scene has none."""
        if self._distractor is None:
            return np.full(3, np.nan)
        return self.data.mocap_pos[self._distractor].copy()

    def place_distractor(self, xy: tuple[float, float] | np.ndarray) -> None:
        """Put the distractor at ``xy`` (m) on the floor (it collides with nothing)."""
        if self._distractor is None:
            raise TwinError("this scene has no distractor (use SCENE_DISTRACTOR)")
        with self.lock:
            self.data.mocap_pos[self._distractor, :2] = xy
            mujoco.mj_forward(self.model, self.data)

    def get_state(self) -> np.ndarray:
        """Full integration state (positions, velocities, controls, warm-start), shape (k,)."""
        with self.lock:
            spec = mujoco.mjtState.mjSTATE_INTEGRATION
            state = np.empty(mujoco.mj_stateSize(self.model, spec))
            mujoco.mj_getState(self.model, self.data, state, spec)
            return state

    def set_state(self, state: np.ndarray) -> None:
        """Restore a state from ``get_state`` exactly (same model only). Commands still held
        by a transport delay are not part of a state: they are dropped."""
        spec = mujoco.mjtState.mjSTATE_INTEGRATION
        size = mujoco.mj_stateSize(self.model, spec)
        state = np.asarray(state, dtype=float)
        if state.shape != (size,):
            raise TwinError(f"twin state has shape {state.shape}, expected ({size},): other model?")
        with self.lock:
            self._pending.clear()
            mujoco.mj_setState(self.model, self.data, state, spec)
            mujoco.mj_forward(self.model, self.data)
            if self.pacer is not None:
                self.pacer.restart()

    # ---- actuation -------------------------------------------------------------------------
    def set_targets(self, q: np.ndarray) -> None:
        """Position targets of the six actuators, shape (6,), rad; the actuators see them
        ``servos.delay_s`` of simulated time after ``present()`` (from the first physics step
        that starts then or later)."""
        with self.lock:
            if self.servos.delay_s <= 0.0:
                self.data.ctrl[self._act_idx] = q
            else:
                due = self.present() + self.servos.delay_s
                self._pending.append((due, np.array(q, dtype=float).reshape(len(JOINTS))))

    def set_torque(self, enabled: bool) -> None:
        """Servo power of all joints: off zeroes the position actuators' gains, so the arm is
        limp (joint damping only), as an XL-320 with torque disabled."""
        self.set_joint_torque(np.full(len(JOINTS), enabled))

    def set_joint_torque(self, mask: np.ndarray) -> None:
        """Servo power per joint, ``mask`` shape (6,) bool (True = torque on)."""
        mask = np.asarray(mask, dtype=bool).reshape(len(JOINTS))
        with self.lock:
            m = self.model
            m.actuator_gainprm[self._act_idx, 0] = np.where(mask, self._kp, 0.0)
            m.actuator_biasprm[self._act_idx, :3] = np.where(mask[:, None], self._bias, 0.0)

    def torque_enabled(self) -> bool:
        return bool(np.all(self.model.actuator_gainprm[self._act_idx, 0] > 0))

    def torque_mask(self) -> np.ndarray:
        """Servo power per joint, shape (6,) bool (True = torque on)."""
        return self.model.actuator_gainprm[self._act_idx, 0] > 0

    def targets(self) -> np.ndarray:
        """The latest position targets given, shape (6,), rad (with a transport delay, the
        actuators may still hold older ones: ``applied_targets``)."""
        with self.lock:
            if self._pending:
                return self._pending[-1][1].copy()
            return self.data.ctrl[self._act_idx]

    def applied_targets(self) -> np.ndarray:
        """The targets the actuators hold now, shape (6,), rad."""
        return self.data.ctrl[self._act_idx]

    def step(self, seconds: float | None = None) -> None:
        """Advance physics by ``seconds`` (rounded to whole steps; one step if None); a
        delayed command reaches the actuators at the first step that starts at or after its
        arrival time."""
        n = 1 if seconds is None else max(1, round(seconds / self.timestep))
        with self.lock:
            while n > 0 and self._pending:
                self._apply_due()
                if not self._pending:
                    break
                ahead = self._pending[0][0] - self.time
                k = min(n, max(1, math.ceil(ahead / self.timestep - 1e-9)))
                mujoco.mj_step(self.model, self.data, nstep=k)
                n -= k
            self._apply_due()
            if n > 0:
                mujoco.mj_step(self.model, self.data, nstep=n)

    def present(self) -> float:
        """Simulated time now, s: the pacer's (wall time mapped to simulated time, between this
        physics step and the next once caught up), else the physics' own time."""
        pacer = self.pacer
        return self.time if pacer is None else max(self.time, pacer.target_time())

    def joint_positions_now(self) -> np.ndarray:
        """Joint angles at ``present()``, shape (6,), rad: the last physics step's, carried on
        by their velocities to the present (less than one 5 ms step: a servo sampled between
        two steps). Without a pacer, ``joint_positions()``."""
        q = self.joint_positions()
        # at most one step: a caller that did not catch up reads the last step's carried on
        # no further than its own length
        ahead = min(self.present() - self.time, self.timestep)
        return q + self.joint_velocities() * ahead if ahead > 0 else q

    def catch_up(self) -> None:
        """Bring the physics up to the present of the twin's pacer (its real-time loop steps it
        to the last physics step at or before the wall time; ``joint_positions_now`` reads the
        joints at the present) before a request reads or writes the state; does nothing
        without a pacer (the caller's steps are the time). Emulators call it under ``lock``
        so that nothing steps between the catch-up and their reading."""
        pacer = self.pacer
        if pacer is not None:
            with self.lock:
                pacer.catch_up(request=True)

    def _apply_due(self) -> None:
        # 1e-9 s: simulated time is a sum of float steps (guess, far below one 5 ms step).
        while self._pending and self._pending[0][0] <= self.time + 1e-9:
            self.data.ctrl[self._act_idx] = self._pending.popleft()[1]

    # ---- queries (index arrays: every one returns a new array) ------------------------------
    def joint_positions(self) -> np.ndarray:
        """Shape (6,), rad."""
        return _take(self.data.qpos, self._reading[0])

    def joint_reading(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
        """Joint angles (6,) rad, velocities (6,) rad/s, actuator torques (6,) N.m (new
        arrays) and the simulated time, s, taken together under ``lock``: what an arm reads
        each control tick, in one call."""
        with self.lock:
            return (
                self.joint_positions(), self.joint_velocities(), self.joint_torques(),
                float(self.data.time),
            )  # fmt: skip

    def joint_velocities(self) -> np.ndarray:
        """Shape (6,), rad/s."""
        return _take(self.data.qvel, self._reading[1])

    def joint_torques(self) -> np.ndarray:
        """Actuator torques, shape (6,), N.m."""
        return _take(self.data.actuator_force, self._reading[2])

    def max_torques(self) -> np.ndarray:
        """Actuator force limits, shape (6,), N.m."""
        return self.model.actuator_forcerange[self._act_idx, 1]

    def ball_position(self) -> np.ndarray:
        """Ball centre, shape (3,), m (world frame, z up, origin at the arm's base)."""
        return self.data.qpos[self._ball_qpos : self._ball_qpos + 3].copy()

    def ball_speed(self) -> float:
        """Linear speed of the ball, m/s."""
        # fixed-order sum, not BLAS's dot (the settle it decides is the same on every machine)
        return norm(self.data.qvel[self._ball_qvel : self._ball_qvel + 3])

    def end_effector_position(self) -> np.ndarray:
        """Tool tip, shape (3,), m."""
        return self.data.site_xpos[self._tip_site].copy()

    def warnings(self) -> dict[str, int]:
        """MuJoCo warnings raised since the last reset: name -> count (empty when clean)."""
        out = {}
        for i, w in enumerate(self.data.warning):
            if w.number > 0:
                out[mujoco.mjtWarning(i).name] = int(w.number)
        return out

    # ---- rendering -------------------------------------------------------------------------
    def render(self, camera: str = "overhead", size: tuple[int, int] | None = None) -> np.ndarray:
        """Render a named camera, shape (H, W, 3), BGR uint8."""
        h, w = size or self.render_size
        with self.lock:
            self._leave_inherited_renderers()
            renderer = self._renderers.get((h, w))
            if renderer is None:
                renderer = mujoco.Renderer(self.model, h, w)
                self._renderers[(h, w)] = renderer
            renderer.update_scene(self.data, camera=camera)
        # the scene is a copy: physics may step again while it is drawn
        rgb = renderer.render()
        return np.ascontiguousarray(rgb[:, :, ::-1])

    def _leave_inherited_renderers(self) -> None:
        """In a process forked after this twin rendered (``multiprocessing``'s default on
        Linux, e.g. Gymnasium's ``AsyncVectorEnv``), set the parent's renderers aside untouched;
        this process makes its own on its next render."""
        if self._renderers_pid != os.getpid():
            _INHERITED_RENDERERS.extend(self._renderers.values())
            self._renderers = {}
            self._renderers_pid = os.getpid()

    def close(self) -> None:
        """Free the renderers' GL contexts (only those this process made)."""
        self._leave_inherited_renderers()
        for r in self._renderers.values():
            r.close()
        self._renderers.clear()

    def __del__(self) -> None:
        with contextlib.suppress(Exception):
            self.close()
