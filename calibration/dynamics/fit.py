"""The fit of the twin's servos to a recording, with ``mujoco.sysid`` (Gauss-Newton least
squares over rollouts of the twin's arm).

The model fitted is the twin's arm alone (``sim/models/ergo_jr.xml``: its links, masses and
joints; the scene's physics step and integrator; no contacts, as the excitation touches
nothing), with a joint-position sensor per joint. Its parameters (a ``mujoco.sysid``
``ParameterDict``), per joint: kp (N.m/rad), damping (N.m.s/rad), armature (kg.m^2) and
frictionloss (N.m), each fitted as the log of its ratio to the nominal twin's
(``sim.servo_model.NOMINAL``), so that all are of one scale; and the command transport delay,
in units of 10 ms. The torque ceiling is not fitted: it is the XL-320's stall torque
(datasheet), where the twin has it.

The delay first: the nominal servos are rolled out at delays from 0 to ``MAX_DELAY_S`` in
``DELAY_GRID_S`` steps and the best one starts the fit. A rollout applies each command from
its time plus the delay, averaged over the physics step it lands in (so that the cost is
continuous in the delay; ``delayed_control``).

Residual: predicted minus measured joint angles at the measured times, every joint, over
every training segment (one ``ModelSequences`` per segment), as the likelihood of a rounded,
slightly mistimed reading (``calibration.dynamics.noise``).
Confidence intervals: ``mujoco.sysid.calculate_intervals`` (95 %) on the log-parameters, from
the Jacobian at the optimum, turned back into values (so they are not symmetric).

The held-out segment is never fitted: its RMS error, nominal against fitted, is the check.
Units: rad, s, N.m, kg.m^2.
"""

from __future__ import annotations

import dataclasses
import io
import logging
import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from calibration.dynamics import noise, uncertainty
from calibration.dynamics.excitation import HELD_OUT_NAME as HELD_OUT
from calibration.dynamics.recording import Recording, RecordingError, servo_goals
from calibration.store import CalibrationError
from robot.spec import ERGO_JR_JOINTS
from sim.servo_model import NOMINAL, ServoModel

log = logging.getLogger(__name__)

FITTED = ("kp", "damping", "armature", "frictionloss")
# Bounds of each fitted ratio to nominal (log-space): a factor of 6 either way holds every
# stand-in draw (factors in [1/2.3, 2.3]) and any servo near the XL-320 (guess).
RATIO_BOUNDS = {
    "kp": (1 / 6, 6.0),
    "damping": (1 / 6, 6.0),
    "armature": (1 / 10, 10.0),
    # nominal 0.001 N.m: 0.0001-0.06 N.m, up to 15 % of the stall torque (guess)
    "frictionloss": (0.1, 60.0),
}
DELAY_UNIT_S = 0.01
MAX_DELAY_S = 0.08  # the fit's bound on the delay (guess: no USB-serial link is slower)
DELAY_GRID_S = 0.005  # the first estimate's grid: the twin's physics step
# The first estimate's factors on the nominal damping: a stand-in's time constant damping / kp
# lies within 0.19-5.3x the nominal's (sim/standin/hidden.py's ranges; guess for an arm),
# covered a factor of 2 apart.
DAMPING_GRID = (0.25, 0.5, 1.0, 2.0, 4.0)
MAX_ITERS = 40  # Gauss-Newton iterations (measured: 8-15 reach the optimum on the twin)
# A fitted twin this close to the arm on the held-out trajectory is good whatever the nominal
# does (an arm like the nominal twin): a tenth of an XL-320 position step (0.29 deg; guess)
RMS_FLOOR_RAD = math.radians(0.03)


class FitError(CalibrationError):
    """The fit could not be made or is not to be trusted; the message is one line."""


@dataclass
class FitResult:
    """What a fit found.

    Attributes:
        servos: the fitted servo model (force limit: nominal).
        intervals: per fitted field, (6, 2) lower and upper 95 % bounds; ``delay_s``: (2,)
            (``calibration.dynamics.uncertainty``: a block jackknife; within the fit's bounds).
        identified: per fitted field, (6,) one line each: "" for a parameter the recording
            identifies, else why it does not (a joint not recorded: "not recorded").
        jackknife_sd: per fitted field, (6,) the jackknife's sd of the log-ratio to nominal,
            what the recording alone says before the model's mismatch (None: not recorded).
        held_out_rms_nominal, held_out_rms_fitted: RMS over the held-out segment of all
            joints, rad.
        held_out_rms_per_joint: {"nominal": (6,), "fitted": (6,)}, rad.
        train_rms_fitted: RMS over the training segments, rad.
        delay_first_s: the grid's first estimate of the delay, s.
        iterations: optimiser iterations; fit_s: wall time of the fit, s.
    """

    servos: ServoModel
    intervals: dict[str, np.ndarray]
    identified: dict[str, list[str]]
    held_out_rms_nominal: float
    held_out_rms_fitted: float
    held_out_rms_per_joint: dict[str, np.ndarray]
    train_rms_fitted: float
    delay_first_s: float
    iterations: int
    fit_s: float
    notes: list[str] = field(default_factory=list)
    jackknife_sd: dict[str, list[float | None]] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """The payload of ``dynamics.json`` (without the recording's reference)."""
        return {
            "servos": self.servos.to_dict(),
            "intervals_95": {k: np.asarray(v).tolist() for k, v in self.intervals.items()},
            "identifiable": {k: [not why for why in v] for k, v in self.identified.items()},
            "jackknife_sd": dict(self.jackknife_sd),
            "unidentified": {
                f"{joint}.{k}": why
                for k, v in self.identified.items()
                for joint, why in zip(ERGO_JR_JOINTS, v, strict=True)
                if why
            },
            "held_out_rms_rad": {
                "nominal": self.held_out_rms_nominal,
                "fitted": self.held_out_rms_fitted,
                "nominal_per_joint": self.held_out_rms_per_joint["nominal"].tolist(),
                "fitted_per_joint": self.held_out_rms_per_joint["fitted"].tolist(),
            },
            "train_rms_rad": self.train_rms_fitted,
            "delay_first_s": self.delay_first_s,
            "iterations": self.iterations,
            "fit_s": round(self.fit_s, 2),
            "notes": list(self.notes),
        }


# ---- the model ---------------------------------------------------------------------------
def arm_spec() -> Any:
    """The twin's arm as a ``mujoco.MjSpec`` for the fit: ergo_jr.xml with the scene's step and
    integrator, contacts off, a ``<joint>_pos`` joint-position sensor per joint."""
    import mujoco

    from sim.twin import JOINTS, MODELS, SCENE

    spec = mujoco.MjSpec.from_file(str(MODELS / "ergo_jr.xml"))
    scene = mujoco.MjSpec.from_file(str(SCENE))  # its <option>: one place for step and solver
    spec.option.timestep = scene.option.timestep
    spec.option.integrator = scene.option.integrator
    spec.option.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
    for name in JOINTS:
        spec.add_sensor(
            name=f"{name}_pos",
            type=mujoco.mjtSensor.mjSENS_JOINTPOS,
            objtype=mujoco.mjtObj.mjOBJ_JOINT,
            objname=name,
        )
    return spec


def _indices(model: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    from sim.twin import JOINTS

    act = np.array([model.actuator(j).id for j in JOINTS])
    dof = np.array([model.joint(j).dofadr[0] for j in JOINTS])
    qpos = np.array([model.joint(j).qposadr[0] for j in JOINTS])
    return act, dof, qpos


def delayed_control(
    command_t: np.ndarray, command: np.ndarray, times: np.ndarray, delay: float, dt: float
) -> np.ndarray:
    """The actuators' targets per physics step: each command held from ``command_t + delay``
    (before the first: the first), averaged over each step ``[t, t + dt)`` (continuous in the
    delay). Shapes: (C,), (C, n), (K,) -> (K, n); s, rad."""
    c = np.asarray(command, float)
    s = np.asarray(command_t, float) + delay
    # F(t) = integral of the held command; piecewise linear with knots at the switch times
    knots = np.concatenate([[s[0] - 1.0], s, [max(s[-1], times[-1] + dt) + 1.0]])
    values = np.concatenate([c[:1], c, c[-1:]])
    seg = np.diff(knots)[:, None] * values[:-1]
    cum = np.vstack([np.zeros((1, c.shape[1])), np.cumsum(seg, axis=0)])

    def integral(t: np.ndarray) -> np.ndarray:
        return np.stack([np.interp(t, knots, cum[:, j]) for j in range(c.shape[1])], axis=1)

    return (integral(times + dt) - integral(times)) / dt


def simulate(
    servos: ServoModel,
    command_t: np.ndarray,
    command: np.ndarray,
    measured_t: np.ndarray,
    q0: np.ndarray,
    spec: Any = None,
) -> np.ndarray:
    """Roll the twin's arm with ``servos`` through a segment's commands from rest at ``q0``;
    its joint angles at ``measured_t``. Shapes: (C,), (C, n), (M,), (n,) -> (M, n); s, rad."""
    import mujoco
    from mujoco import rollout

    from sim.servo_model import write_model

    model = (spec if spec is not None else arm_spec()).compile()
    act, dof, qpos = _indices(model)
    write_model(model, act, dof, servos)
    data = mujoco.MjData(model)
    dt = float(model.opt.timestep)
    steps = math.ceil((measured_t[-1] - command_t[0]) / dt) + 1
    times = command_t[0] + np.arange(steps) * dt
    ctrl = np.zeros((steps, model.nu))
    ctrl[:, act] = delayed_control(command_t, command, times, servos.delay_s, dt)
    data.qpos[qpos] = q0
    data.time = command_t[0]
    mujoco.mj_forward(model, data)
    state0 = np.empty(mujoco.mj_stateSize(model, mujoco.mjtState.mjSTATE_FULLPHYSICS))
    mujoco.mj_getState(model, data, state0, mujoco.mjtState.mjSTATE_FULLPHYSICS)
    states, _ = rollout.rollout(model, data, state0, ctrl)
    states = np.squeeze(states, axis=0)
    t = np.concatenate([[command_t[0]], states[:, 0]])
    q = np.vstack([q0[None, :], states[:, 1 + qpos]])
    return np.stack([np.interp(measured_t, t, q[:, j]) for j in range(q.shape[1])], axis=1)


# ---- the fit -----------------------------------------------------------------------------
def _segments(rec: Recording) -> list[str]:
    return [s for s in rec.segment_names if s != HELD_OUT]


def _servos_from(values: dict[str, np.ndarray], delay: float) -> ServoModel:
    return NOMINAL.replace(**{k: tuple(values[k]) for k in FITTED}, delay_s=float(delay))


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x)))) if x.size else math.nan


def segment_error(servos: ServoModel, rec: Recording, name: str, spec: Any = None) -> np.ndarray:
    """Predicted minus measured joint angles over one segment, shape (M, n), rad."""
    ct, cmd, mt, meas = rec.segment(name)
    pred = simulate(servos, ct, cmd, mt, meas[0], spec)
    return pred - meas


def reading_noise(rec: Recording, mt: np.ndarray, meas: np.ndarray) -> tuple[np.ndarray, Any]:
    """What the fit's residual needs of a segment's readings (``calibration.dynamics.noise``):
    half a raw unit per joint (n,) and each reading's noise before rounding (M, n), rad."""
    return noise.half_steps(rec.meta, meas.shape[1]), noise.reading_sigma(
        mt, meas, noise.timed(rec.meta)
    )


def readings_residual(err: np.ndarray, rec: Recording, mt: np.ndarray, meas: np.ndarray):
    """The fit's residual of a segment's errors (predicted minus measured, (M, n) rad):
    ``noise.residual``, dimensionless, (M, n)."""
    half, sigma = reading_noise(rec, mt, meas)
    return noise.residual(err, half, sigma)


def training_cost(servos: ServoModel, rec: Recording, segments: list[str], spec: Any) -> float:
    """The fit's cost of ``servos`` over ``segments``: the sum of the squared residuals
    (``readings_residual``)."""
    total = 0.0
    for name in segments:
        _, _, mt, meas = rec.segment(name)
        err = segment_error(servos, rec, name, spec)
        total += float(np.sum(readings_residual(err, rec, mt, meas) ** 2))
    return total


def first_guess(rec: Recording, spec: Any) -> tuple[float, float]:
    """Where the fit starts: the delay (s, on ``DELAY_GRID_S`` steps up to ``MAX_DELAY_S / 2``)
    and the factor on the nominal damping (one of ``DAMPING_GRID``: a slower or faster servo)
    whose rollout fits the training best. Started from the nominal servos alone, the delay took
    the grid's end on the stand-ins (their servos 2-3x slower than nominal: a late response
    looks like a long delay), and Gauss-Newton stopped 2-3 ms of delay and half the armature
    away from a better optimum (measured, docs/dynamics.md)."""
    best, best_cost = (0.0, 1.0), math.inf
    for c in DAMPING_GRID:
        damped = NOMINAL.replace(damping=tuple(NOMINAL.array("damping") * c))
        for d in np.arange(0.0, MAX_DELAY_S / 2 + 1e-9, DELAY_GRID_S):
            cost = training_cost(damped.replace(delay_s=float(d)), rec, _segments(rec), spec)
            if cost < best_cost:
                best, best_cost = (float(d), float(c)), cost
    return best


def fit(rec: Recording, max_iters: int = MAX_ITERS, verbose: bool = False) -> FitResult:
    """Fit the servos to ``rec``'s training segments; check on its held-out segment.

    Raises:
        FitError: the optimiser failed, or its result is not finite, or it does not move the
            held-out trajectory closer to the arm than the nominal twin does.
    """
    from sim.twin import JOINTS

    t_start = time.monotonic()
    try:
        from mujoco import sysid
    except ImportError:  # pragma: no cover - the dependency is declared
        raise FitError("mujoco.sysid is missing: pip install 'mujoco[sysid]==4.0.0'") from None
    # absl's WARNING "Sensor data dimension 6 does not match model sensor dimension 9" comes
    # once per rollout: the fit compares rolled-out joint states, not the model's sensors (on
    # purpose, below); it told a user nothing, so only errors are shown
    logging.getLogger("absl").setLevel(logging.INFO if verbose else logging.ERROR)
    if HELD_OUT not in rec.segment_names:
        raise RecordingError("the recording has no held-out segment: record again")
    rec = dataclasses.replace(rec, command=servo_goals(rec))  # as the servos held them
    spec = arm_spec()
    delay0, damping0 = first_guess(rec, spec)
    params = sysid.ParameterDict()
    # a joint without its own segment keeps the nominal servo (frozen: not fitted)
    excited = [name for name in JOINTS if name in rec.segment_names]
    for k, name in enumerate(JOINTS):
        for field_name in FITTED:
            lo, hi = RATIO_BOUNDS[field_name]
            nominal = NOMINAL.array(field_name)[k]
            start = math.log(damping0) if field_name == "damping" and name in excited else 0.0
            params.add(
                sysid.Parameter(
                    f"{name}.{field_name}", start, math.log(lo), math.log(hi),
                    frozen=name not in excited,
                    modifier=_modifier(name, field_name, nominal),
                )
            )  # fmt: skip
    params.add(
        sysid.Parameter(
            "delay",
            delay0 / DELAY_UNIT_S,
            0.0,
            MAX_DELAY_S / DELAY_UNIT_S,
            modifier=lambda s, p: None,
        )
    )
    segments = _segments(rec)
    sensors = [f"{j}_pos" for j in JOINTS]
    # each segment's commands, by index: the control series given to mujoco.sysid carries
    # only that index (the rollout builds the delayed targets from the commands themselves)
    raw: list[tuple[np.ndarray, np.ndarray]] = []
    sequences = []
    noise_of: dict[int, tuple[np.ndarray, ...]] = {}  # by the measured series' id
    model0 = spec.compile()
    _, _, qpos_idx = _indices(model0)
    dt = float(model0.opt.timestep)
    for name in segments:
        ct, cmd, mt, meas = rec.segment(name)
        t0 = ct[0]
        qpos = np.zeros(model0.nq)
        qpos[qpos_idx] = meas[0]
        state0 = sysid.create_initial_state(model0, qpos, np.zeros(model0.nv))
        n_steps = math.ceil((mt[-1] - t0) / dt) + 1
        control = sysid.TimeSeries(
            np.arange(n_steps) * dt, np.full((n_steps, model0.nu), float(len(raw)))
        )
        raw.append((ct - t0, cmd))
        measured = sysid.TimeSeries.from_names(mt - t0, meas, model0, names=sensors)
        noise_of[id(measured)] = (mt - t0, *reading_noise(rec, mt, meas))
        sequences.append(
            sysid.ModelSequences(
                name, spec, name, state0, control, measured, allow_missing_sensors=True
            )
        )

    act_idx, _, _ = _indices(model0)

    def rollout_with_delay(models, datas, control_signal, initial_states, param_dicts, **mapping):
        n_chunks = len(control_signal) // len(param_dicts)
        shifted = []
        for i, ts in enumerate(control_signal):
            delay = float(param_dicts[i // n_chunks]["delay"].value[0]) * DELAY_UNIT_S
            ct, cmd = raw[round(float(ts.data[0, 0]))]
            u = np.zeros((len(ts.times), model0.nu))
            u[:, act_idx] = delayed_control(ct, cmd, ts.times, delay, dt)
            shifted.append(sysid.TimeSeries(ts.times, u))
        return sysid.sysid_rollout(models, datas, shifted, initial_states, **mapping)

    def positions_residual(params, pred, meas, model, return_pred_all, state=None, **_):
        # The joint angles from the rolled-out states, stamped with their own times (a
        # rollout's sensor rows are computed before each step, a step earlier than the times
        # they are given: 5 ms of delay the fit would miss).
        times, half, sigma = noise_of[id(meas)]
        pred = sysid.TimeSeries(state[:, 0], state[:, 1 + qpos_idx], meas.signal_mapping)
        meas = sysid.apply_delayed_ts_window(meas, pred, 0.0, 0.0)
        pred = pred.resample(meas.times)
        sigma = sigma[np.clip(np.searchsorted(times, meas.times - 1e-9), 0, len(times) - 1)]
        return noise.residual(pred.data - meas.data, half, sigma), pred, meas

    residual_fn = sysid.build_residual_fn(
        models_sequences=sequences,
        custom_rollout=rollout_with_delay,
        modify_residual=positions_residual,
        n_threads=2,
    )
    try:
        quiet = {} if verbose else {"output": io.StringIO()}  # the backend's iteration log
        # The armature last: its effect is nearly a delay's (its time constant, armature /
        # damping, is a few ms), so fitted together from afar the two slide along one valley
        # (measured: 2-3 ms of delay traded for half the armature, docs/dynamics.md). First
        # everything else with the armature nominal, then all from there.
        for name in excited:
            params[f"{name}.armature"].frozen = True
        params, _ = sysid.optimize(
            params, residual_fn, optimizer="mujoco", verbose=verbose, max_iters=max_iters,
            **quiet,
        )  # fmt: skip
        for name in excited:
            params[f"{name}.armature"].frozen = False
        opt_params, result = sysid.optimize(
            params, residual_fn, optimizer="mujoco", verbose=verbose, max_iters=max_iters,
            **quiet,
        )  # fmt: skip
        # The cost has kinks where the delay crosses a physics step (a command lands in the
        # next step), where Gauss-Newton can stop short: the delay is searched again on a
        # 1 ms grid with the other parameters fitted, and the fit resumed from the best.
        moved = _refine_delay(opt_params, rec, segments, spec)
        if moved:
            opt_params, result = sysid.optimize(
                opt_params, residual_fn, optimizer="mujoco", verbose=verbose,
                max_iters=max_iters, **quiet,
            )  # fmt: skip
        x = opt_params.as_vector()
    except (ValueError, RuntimeError, FloatingPointError, np.linalg.LinAlgError) as exc:
        raise FitError(f"the optimiser failed ({type(exc).__name__}: {exc})") from None
    if not np.all(np.isfinite(x)):
        raise FitError(f"the fit diverged (parameters {x.tolist()})")
    values = _values(opt_params)
    delay = float(opt_params["delay"].value[0]) * DELAY_UNIT_S
    try:
        servos = _servos_from(values, min(delay, MAX_DELAY_S))
    except ValueError as exc:
        raise FitError(f"the fitted servos are not valid ({exc})") from None
    nominal_err = segment_error(NOMINAL, rec, HELD_OUT, spec)
    fitted_err = segment_error(servos, rec, HELD_OUT, spec)
    train = np.concatenate([segment_error(servos, rec, s, spec) for s in segments])
    out = FitResult(
        servos=servos,
        intervals={},
        identified={},
        held_out_rms_nominal=_rms(nominal_err),
        held_out_rms_fitted=_rms(fitted_err),
        held_out_rms_per_joint={
            "nominal": np.sqrt(np.mean(nominal_err**2, axis=0)),
            "fitted": np.sqrt(np.mean(fitted_err**2, axis=0)),
        },
        train_rms_fitted=_rms(train),
        delay_first_s=delay0,
        iterations=len(result.extras.get("objective", [])) if hasattr(result, "extras") else 0,
        fit_s=time.monotonic() - t_start,
    )
    if out.held_out_rms_fitted > max(out.held_out_rms_nominal, RMS_FLOOR_RAD):
        raise FitError(
            f"the fitted twin is no closer to the arm than the nominal one on the held-out "
            f"trajectory (RMS {math.degrees(out.held_out_rms_fitted):.2f} deg against "
            f"{math.degrees(out.held_out_rms_nominal):.2f} deg): the recording does not "
            "show the servos' dynamics (an arm blocked, loose, or not this model)"
        )
    # the intervals last: a fit refused above needs none (their rollouts cost a fit's third)
    out.intervals, out.identified, out.jackknife_sd = _intervals(
        values, delay, rec, segments, spec, excited
    )
    out.fit_s = time.monotonic() - t_start
    if len(excited) < len(JOINTS):
        kept = [j for j in JOINTS if j not in excited]
        out.notes.append(f"{', '.join(kept)} not recorded: nominal servos kept")
    for field_name in FITTED:
        lo, hi = RATIO_BOUNDS[field_name]
        ratio = values[field_name] / NOMINAL.array(field_name)
        at = [JOINTS[k] for k in range(6) if ratio[k] < lo * 1.01 or ratio[k] > hi * 0.99]
        if at:
            out.notes.append(f"{field_name} of {', '.join(at)} at the fit's bound")
    return out


def _intervals(
    values: dict[str, np.ndarray],
    delay: float,
    rec: Recording,
    segments: list[str],
    spec: Any,
    excited: list[str],
) -> tuple[dict[str, np.ndarray], dict[str, list[str]], dict[str, list[float | None]]]:
    """The 95 % intervals of the fitted values (per field (6, 2), the delay (2,)), per field
    why each joint's value is not identified ("" where it is) and the jackknife's sd of its
    log-ratio (None: not recorded); the block jackknife of ``calibration.dynamics.uncertainty``
    on the fit's own weighted residuals."""
    from sim.twin import JOINTS

    names = [f"{j}.{f}" for f in FITTED for j in excited] + ["delay"]
    data = []
    for name in [*segments, HELD_OUT]:
        _, _, mt, meas = rec.segment(name)
        data.append((name, mt, meas, uncertainty.block_ids(mt)))
    blocks = np.concatenate(
        [np.repeat(b + 1000 * k, len(JOINTS)) for k, (*_, b) in enumerate(data)]
    )
    fitted = np.concatenate([np.full(len(mt) * len(JOINTS), n != HELD_OUT) for n, mt, *_ in data])
    nominal = {f: NOMINAL.array(f) for f in FITTED}
    x0 = np.array(
        [
            math.log(values[f][JOINTS.index(j)] / nominal[f][JOINTS.index(j)])
            for f in FITTED
            for j in excited
        ]
        + [delay / DELAY_UNIT_S]
    )

    def residuals(x: np.ndarray) -> np.ndarray:
        v = {f: values[f].copy() for f in FITTED}
        for i, name in enumerate(names[:-1]):
            joint, f = name.split(".")
            v[f][JOINTS.index(joint)] = nominal[f][JOINTS.index(joint)] * math.exp(x[i])
        servos = _servos_from(v, max(0.0, float(x[-1]) * DELAY_UNIT_S))
        return np.concatenate(
            [
                readings_residual(segment_error(servos, rec, name, spec), rec, mt, meas).ravel()
                for name, mt, meas, _ in data
            ]
        )

    lin = uncertainty.linearise(residuals, x0, names, blocks, fitted)
    iv = uncertainty.jackknife(lin)
    bounds = {n: tuple(math.log(b) for b in RATIO_BOUNDS[n.split(".")[1]]) for n in names[:-1]}
    why = uncertainty.identification(iv, bounds)
    intervals: dict[str, np.ndarray] = {}
    identified: dict[str, list[str]] = {}
    sd: dict[str, list[float | None]] = {}
    for f in FITTED:
        lo, hi = values[f].copy(), values[f].copy()
        identified[f] = ["not recorded: the nominal servo kept"] * len(JOINTS)
        sd[f] = [None] * len(JOINTS)
        # no wider than the fit's bounds: the fit cannot put a value beyond them
        floor, ceiling = (nominal[f] * r for r in RATIO_BOUNDS[f])
        for j in excited:
            i, k = names.index(f"{j}.{f}"), JOINTS.index(j)
            half = uncertainty.with_mismatch(min(iv.half[i], 700.0), rec.meta.get("backend"), f)
            lo[k] = max(values[f][k] * math.exp(-half), floor[k])
            hi[k] = min(values[f][k] * math.exp(half), ceiling[k])
            identified[f][k] = why[f"{j}.{f}"].reason
            sd[f][k] = float(np.sqrt(max(iv.cov[i, i], 0.0)))
        intervals[f] = np.stack([lo, hi], axis=1)
    dh = iv.half[-1] * DELAY_UNIT_S
    intervals["delay_s"] = np.array([max(0.0, delay - dh), delay + dh])
    return intervals, identified, sd


def _values(opt_params: Any) -> dict[str, np.ndarray]:
    from sim.twin import JOINTS

    return {
        f: NOMINAL.array(f) * np.exp([float(opt_params[f"{j}.{f}"].value[0]) for j in JOINTS])
        for f in FITTED
    }


def _refine_delay(opt_params: Any, rec: Recording, segments: list[str], spec: Any) -> bool:
    """Set the delay to the best of a 1 ms grid within +-``2 DELAY_GRID_S`` of the fitted one,
    the other parameters as fitted; whether it moved."""
    values = _values(opt_params)
    fitted = float(opt_params["delay"].value[0]) * DELAY_UNIT_S
    grid = fitted + np.arange(-2 * DELAY_GRID_S, 2 * DELAY_GRID_S + 1e-9, 0.001)
    grid = grid[(grid >= 0.0) & (grid <= MAX_DELAY_S)]
    costs = [
        training_cost(_servos_from(values, float(d)), rec, segments, spec)
        for d in np.append(grid, fitted)
    ]
    best = int(np.argmin(costs))
    if best == len(grid) or costs[best] >= costs[-1]:
        return False
    opt_params["delay"].value[:] = grid[best] / DELAY_UNIT_S
    return True


def _modifier(joint: str, field_name: str, nominal: float):
    """The ``mujoco.sysid`` modifier that writes one log-ratio parameter into the spec."""

    def apply(spec: Any, p: Any) -> None:
        value = nominal * math.exp(float(p.value[0]))
        if field_name == "kp":
            act = spec.actuator(joint)
            act.gainprm[0] = value
            act.biasprm[1] = -value
        elif field_name == "damping":
            spec.joint(joint).damping[0] = value
        else:
            setattr(spec.joint(joint), field_name, value)

    return apply
