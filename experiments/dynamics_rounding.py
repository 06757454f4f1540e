"""What an XL-320's 10-bit positions do to the servos' fit, on the twin in process (no bus, no
timing error): a stand-in's hidden servos recorded with readings and goals exact, or rounded to
the XL-320's raw unit (300 deg / 1023) on a grid of random phase per joint, as a Dynamixel
servo rounds them; each recording fitted as ``ergo calibrate dynamics --recording`` does, and
once more with the rounding hidden from the fit (the recording's ``position_resolution``
removed: the goals taken as sent, the readings as exact). Per case, each fitted parameter's
error against the hidden one, whether its 95 % interval holds it, the delay (the twin applies
a delayed command at its next 5 ms step: the hidden delay rounded up to 5 ms is the truth).

    python experiments/dynamics_rounding.py --seed 300 [--cases exact both both-hidden]
        [--keep DIR]

Reads the stand-in's hidden servos (``sim.standin.hidden.draw_hidden``, as the bench does);
the fit never sees them. ``--keep DIR``: each case's recording and result kept, a case done
before not done again.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from calibration.dynamics import excitation  # noqa: E402
from calibration.dynamics.fit import fit  # noqa: E402
from calibration.dynamics.recording import Recording, record  # noqa: E402
from robot.arm import JointState  # noqa: E402
from sim.arm import SimArm  # noqa: E402
from sim.standin.hidden import draw_hidden  # noqa: E402
from sim.twin import Twin  # noqa: E402

STEP_RAD = math.radians(300.0) / 1023  # the XL-320's raw unit (ROBOTIS e-manual)
FIELDS = ("kp", "damping", "armature", "frictionloss")
# case: (readings rounded, goals rounded, the fit told the resolution)
CASES = {
    "exact": (False, False, False),
    "readings": (True, False, False),
    "goals": (False, True, True),
    "both": (True, True, True),
    "both-hidden": (True, True, False),
}


class RoundingArm(SimArm):
    """The twin's arm with an XL-320's rounding of readings and goals (grid ``phase``)."""

    def __init__(self, twin: Twin, phase: np.ndarray, readings: bool, goals: bool) -> None:
        super().__init__(twin)
        self.phase, self.readings, self.goals = phase, readings, goals

    def _round(self, q: np.ndarray) -> np.ndarray:
        return self.phase + STEP_RAD * np.rint((np.asarray(q, float) - self.phase) / STEP_RAD)

    def _read(self) -> JointState:
        s = super()._read()
        if not self.readings:
            return s
        return JointState.from_positions(
            self._round(s.positions), s.timestamp, velocities=s.velocities, loads=s.loads,
            temperatures=s.temperatures,
        )  # fmt: skip

    def _send(self, positions: np.ndarray) -> None:
        self.twin.set_targets(self._round(positions) if self.goals else positions)

    @property
    def position_resolution(self) -> np.ndarray:
        return np.full(6, STEP_RAD if self.readings else 0.0)


def recording(seed: int, readings: bool, goals: bool) -> Recording:
    servos = draw_hidden(seed).servos
    twin = Twin(servos=servos)
    phase = np.random.default_rng(seed).uniform(0.0, STEP_RAD, 6)
    arm = RoundingArm(twin, phase, readings, goals)

    class Clock:
        def now(self) -> float:
            return twin.time

        def advance(self, seconds: float) -> None:
            twin.step(seconds)

    with arm:
        arm.set_torque(True)
        return record(
            # one repeat: the recording the table of docs/results_dynamics.md was measured on
            arm, Clock(), excitation.plan(arm.spec, repeats=1), reads_per_tick=2,
            meta={"rig_id": f"rounding-{seed}", "backend": "twin"},
        )  # fmt: skip


def one(seed: int, case: str, work: Path) -> dict:
    readings, goals, told = CASES[case]
    rec = recording(seed, readings, goals)
    if not told:
        rec.meta["position_resolution"] = [0.0] * 6
    rec.save(work / f"rounding-{seed}-{case}.npz")
    t0 = time.monotonic()
    result = fit(rec)
    truth = draw_hidden(seed).servos
    twin_dt = 0.005
    out: dict = {"seed": seed, "case": case, "fit_s": round(time.monotonic() - t0, 1)}
    out["delay_ms"] = {
        "fitted": result.servos.delay_s * 1e3,
        "applied": math.ceil(truth.delay_s / twin_dt - 1e-9) * twin_dt * 1e3,
    }
    out["held_out_rms_deg"] = math.degrees(result.held_out_rms_fitted)
    for f in FIELDS:
        t, v = truth.array(f), result.servos.array(f)
        lo, hi = result.intervals[f].T
        out[f] = {
            "rel_err": (v / t - 1).tolist(),
            "covered": ((lo <= t) & (t <= hi)).tolist(),
            "identified": [not w for w in result.identified[f]],
        }
    return out


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seed", type=int, default=300)
    p.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES))
    p.add_argument("--keep", type=Path, default=Path("."))
    args = p.parse_args()
    args.keep.mkdir(parents=True, exist_ok=True)
    rows = []
    for case in args.cases:
        kept = args.keep / f"rounding-{args.seed}-{case}.json"
        if kept.exists():
            rows.append(json.loads(kept.read_text()))
            continue
        r = one(args.seed, case, args.keep)
        kept.write_text(json.dumps(r, indent=1))
        rows.append(r)
    print("| case | " + " | ".join(FIELDS) + " | delay fitted / applied, ms | held-out RMS, deg |")
    print("|---|" + "---|" * (len(FIELDS) + 2))
    for r in rows:
        cells = []
        for f in FIELDS:
            e = np.asarray(r[f]["rel_err"]) * 100
            cells.append(f"{e.min():+.0f} .. {e.max():+.0f} % ({sum(r[f]['covered'])} / 6 held)")
        d = r["delay_ms"]
        print(
            f"| {r['case']} | " + " | ".join(cells)
            + f" | {d['fitted']:.1f} / {d['applied']:.0f} | {r['held_out_rms_deg']:.4f} |"
        )  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
