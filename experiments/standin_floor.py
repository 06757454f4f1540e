"""What the stand-ins' "floor" is made of: on recordings kept by ``standin_dynamics.py --keep
DIR``, the hidden servos' own held-out error, how much of it a time shift per reading explains
(the readings' timing jitter: when the host stamps a reading or a command against when the
served twin sampled or applied it), and how far each fitted parameter moves the held-out
trajectory (the hidden servos with one field x1.5, at the readings and on a 1 ms grid: what a
faster bus would see). Reads the hidden files, as the bench does; simulates in one process.

    python experiments/standin_floor.py DIR [DIR ...]

Per rig (``DIR/hidden-BUS-SEED.json`` with ``DIR/sSEED-BUS/dynamics_recording.npz``), one
block: the floor and its delay (the hidden delay plus the best of 0-30 ms of transport, as
``standin_dynamics.truth_floor``), the readings' intervals, the time shift per reading (least
squares over the six joints, readings where the joints move faster than 20 deg/s), the RMS
left once each reading is shifted, and the sensitivities.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from calibration.dynamics.fit import arm_spec, simulate  # noqa: E402
from calibration.dynamics.recording import Recording  # noqa: E402
from sim.servo_model import ServoModel  # noqa: E402
from testkit.standin_truth import read_hidden  # noqa: E402

FIELDS = ("kp", "damping", "armature", "frictionloss")
SCALE = 1.5  # each field's change in the sensitivities (a guess at "clearly wrong")
FAST_RAD_S = math.radians(20.0)  # readings used for the time shift: joints moving this fast
TRANSPORT_S = np.arange(0.0, 0.031, 0.002)  # the floor's search, as standin_dynamics.py


def _rms_deg(x: np.ndarray) -> float:
    return math.degrees(float(np.sqrt(np.mean(np.square(x)))))


def floor(rec: Recording, truth: ServoModel, spec: object) -> tuple[float, float, np.ndarray]:
    """The hidden servos' best held-out RMS (deg), its delay (s) and their prediction (M, n)."""
    ct, cmd, mt, meas = rec.segment("held_out")
    best = None
    for d in truth.delay_s + TRANSPORT_S:
        pred = simulate(truth.replace(delay_s=float(d)), ct, cmd, mt, meas[0], spec)
        r = _rms_deg(pred - meas)
        if best is None or r < best[0]:
            best = (r, float(d), pred)
    assert best is not None
    return best


def one(hidden: Path, recording: Path) -> None:
    rec = Recording.load_file(recording)
    truth = read_hidden(hidden).servos
    spec = arm_spec()
    ct, cmd, mt, meas = rec.segment("held_out")
    rms, delay, pred = floor(rec, truth, spec)
    err = pred - meas
    v = np.gradient(pred, mt, axis=0)  # rad/s
    shift = np.sum(err * v, axis=1) / np.maximum(np.sum(v * v, axis=1), 1e-12)  # s
    fast = np.sum(v * v, axis=1) > FAST_RAD_S**2
    left = err - v * shift[:, None]
    p5, p50, p95 = np.percentile(shift[fast], [5, 50, 95]) * 1e3
    dm = np.percentile(np.diff(mt), [5, 50, 95, 99]) * 1e3
    dc = np.percentile(np.diff(ct), [5, 50, 95, 99]) * 1e3
    print(f"== {recording.parent.name}")
    print(
        f"   floor {rms:.3f} deg at delay {delay * 1e3:.1f} ms (hidden {truth.delay_s * 1e3:.1f})"
    )
    print(f"   readings every {' / '.join(f'{x:.1f}' for x in dm)} ms (5/50/95/99 %), commands "
          f"every {' / '.join(f'{x:.1f}' for x in dc)} ms")  # fmt: skip
    print(
        f"   time shift per reading ({fast.sum()} of {len(mt)} moving): median {p50:.1f} ms, "
        f"5-95 % {p5:.1f}..{p95:.1f} ms, sd {np.std(shift[fast]) * 1e3:.1f} ms; RMS left once "
        f"shifted {_rms_deg(left):.3f} deg; joint speed RMS "
        f"{math.degrees(float(np.sqrt(np.mean(v**2)))):.0f} deg/s"
    )
    fine = np.arange(mt[0], mt[-1], 0.001)
    base = simulate(truth, ct, cmd, mt, meas[0], spec)
    base_fine = simulate(truth, ct, cmd, fine, meas[0], spec)
    values = truth.to_dict()
    for f in FIELDS:
        changed = truth.replace(**{f: tuple(np.asarray(values[f]) * SCALE)})
        at = _rms_deg(simulate(changed, ct, cmd, mt, meas[0], spec) - base)
        on = _rms_deg(simulate(changed, ct, cmd, fine, meas[0], spec) - base_fine)
        print(
            f"   {f:13s} x{SCALE}: moves it {at:.3f} deg at the readings, {on:.3f} on a 1 ms grid"
        )
    later = truth.replace(delay_s=truth.delay_s + 0.006)
    moved = _rms_deg(simulate(later, ct, cmd, mt, meas[0], spec) - base)
    tau = np.asarray(values["armature"]) / np.asarray(values["damping"]) * 1e3
    print(f"   delay + 6 ms: moves it {moved:.3f} deg; armature / damping {np.round(tau, 1)} ms")


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("dirs", type=Path, nargs="+", help="folders of standin_dynamics.py --keep")
    args = p.parse_args()
    for d in args.dirs:
        for hidden in sorted(d.glob("hidden-*-*.json")):
            bus, seed = hidden.stem.split("-")[1:3]
            recording = d / f"s{seed}-{bus}" / "dynamics_recording.npz"
            if recording.exists():
                one(hidden, recording)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
