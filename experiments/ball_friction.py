"""Can the ball's friction be fitted from tracked positions after a push? A feasibility check
on the twin in one process, with a known changed ball friction (docs/dynamics.md, issue 28).

For each true rolling friction (the ball geom's ``friction[2]``; the scene's is 0.004) and each
launch speed: the ball at its start on the ring, launched rolling along the ring (as a push
leaves it), its centre sampled at a camera's frame rate with Gaussian noise (what a tracker
reports), until it stops. Then the fit: rollouts of the same scene from a guessed launch
(position, velocity) and friction, least squares (``scipy.optimize.least_squares``) on the
sampled positions over the launch's 4 numbers and log(rolling friction), from three starts of
the friction. Prints per case the
frames seen while the ball moved, the roll's length and duration, and the friction fitted.

    .venv/bin/python experiments/ball_friction.py [--rates 15 60] [--noise-mm 0 1]
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import mujoco
import numpy as np
from scipy.optimize import least_squares

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from sim.twin import Twin

ROLLING_TRUE = (0.002, 0.004, 0.008)  # the scene's 0.004 (sim/models/README.md), halved, doubled
SPEEDS = (0.2, 0.4)  # launch speeds, m/s (guesses: a push that moves the ball a few cm)
HORIZON_S = 1.5  # long enough for every roll above to stop (measured: under 0.6 s)
STILL_MPS = 0.005  # below this the ball counts as stopped (guess, 5 mm/s)


class BallScene:
    """The twin's scene, the arm held at rest, and a ball launched from a given state."""

    def __init__(self) -> None:
        self.twin = Twin(render_size=(16, 16))
        m = self.twin.model
        self.gid = m.geom("ball").id
        self.floor = m.geom("floor").id
        self.touched = False
        self.nominal_friction = m.geom_friction[self.gid].copy()
        self.q, self.v = self.twin._ball_qpos, self.twin._ball_qvel
        self.start = self.twin.ball_position()[:2].copy()
        self.r = self.twin.ball_radius

    def roll(self, rolling: float, xy: np.ndarray, vxy: np.ndarray, times: np.ndarray):
        """The ball's centre (N, 2) at ``times`` (s from the launch) and its speed (N,), with
        rolling friction ``rolling``, launched from ``xy`` at ``vxy`` rolling (no slip)."""
        twin, m, d = self.twin, self.twin.model, self.twin.data
        twin.reset()
        m.geom_friction[self.gid] = [self.nominal_friction[0], self.nominal_friction[1], rolling]
        d.qpos[self.q : self.q + 2] = xy
        d.qvel[self.v : self.v + 6] = 0.0
        d.qvel[self.v : self.v + 2] = vxy
        # rolling without slip: omega = z x v / r
        d.qvel[self.v + 3 : self.v + 5] = np.array([-vxy[1], vxy[0]]) / self.r
        mujoco.mj_forward(m, d)
        out, speed = np.empty((len(times), 2)), np.empty(len(times))
        t0 = d.time
        self.touched = False  # whether the ball touched anything but the floor (wall, kerb)
        for i, t in enumerate(times):
            while d.time - t0 < t - 1e-9:
                mujoco.mj_step(m, d)
                self.touched |= any(
                    self.gid in (c.geom1, c.geom2) and self.floor not in (c.geom1, c.geom2)
                    for c in d.contact[: d.ncon]
                )
            out[i] = d.qpos[self.q : self.q + 2]
            speed[i] = np.hypot(*d.qvel[self.v : self.v + 2])
        return out, speed


# The fit's starts for the rolling friction (the best residual wins): the scene's value and a
# factor 4 either side (guesses, spanning the cases above).
STARTS = (0.001, 0.004, 0.016)


def fit(scene: BallScene, times: np.ndarray, seen: np.ndarray) -> tuple[float, float]:
    """Least squares over (x, y, vx, vy, log rolling) from each of ``STARTS``; returns the
    rolling friction fitted and the RMS residual, mm."""
    v0 = (seen[1] - seen[0]) / (times[1] - times[0])

    def residual(p: np.ndarray) -> np.ndarray:
        pos, _ = scene.roll(math.exp(p[4]), p[:2], p[2:4], times)
        return ((pos - seen) * 1000.0).ravel()  # mm

    best = None
    for start in STARTS:
        p0 = np.array([*seen[0], *v0, math.log(start)])
        sol = least_squares(residual, p0, diff_step=1e-3, max_nfev=200)
        if best is None or sol.cost < best.cost:
            best = sol
    return math.exp(best.x[4]), float(np.sqrt(np.mean(best.fun**2)))


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--rates", type=float, nargs="+", default=[15.0, 60.0], help="frames/s")
    p.add_argument("--noise-mm", type=float, nargs="+", default=[0.0, 1.0])
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args()
    rng = np.random.default_rng(args.seed)
    scene = BallScene()
    # along the ring at the ball's start: the tangent
    tangent = np.array([-scene.start[1], scene.start[0]]) / np.linalg.norm(scene.start)
    print("true rolling, speed m/s, fps, noise mm: frames moving, roll mm, roll s -> fitted")
    for rolling in ROLLING_TRUE:
        for speed in SPEEDS:
            fine = np.arange(0.0, HORIZON_S, 0.005)
            path, spd = scene.roll(rolling, scene.start, speed * tangent, fine)
            wall = " (touched the wall)" if scene.touched else ""
            moving = spd > STILL_MPS
            stop_s = float(fine[moving][-1]) if moving.any() else 0.0
            length = float(np.sum(np.linalg.norm(np.diff(path, axis=0), axis=1)) * 1000)
            for rate in args.rates:
                times = np.arange(0.0, HORIZON_S, 1.0 / rate)
                truth, _ = scene.roll(rolling, scene.start, speed * tangent, times)
                frames = int(np.sum(times <= stop_s))
                for noise in args.noise_mm:
                    seen = truth + rng.normal(0.0, noise / 1000.0, truth.shape)
                    got, rms = fit(scene, times, seen)
                    print(
                        f"{rolling:.3f}, {speed:.1f}, {rate:.0f}, {noise:.1f}: {frames} frames, "
                        f"{length:.0f} mm, {stop_s:.2f} s -> {got:.4f} ({got / rolling - 1:+.0%}),"
                        f" residual {rms:.2f} mm{wall}",
                        flush=True,
                    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
