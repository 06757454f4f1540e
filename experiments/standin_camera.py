"""The camera's intervals on stand-in rigs: for each seed, ``ergo twin serve --stand-in SEED``
with its camera, ``ergo calibrate camera`` with the chessboard held up by the stand-in's
hands (``testkit.standin_owner.Owner.calibrate_camera``, the guide's command), then fx, fy,
cx and cy against the hidden camera's: the error, the reported sd, the error in sds, and
whether the reported 95 % interval holds the hidden value. Prints a table and a JSON summary.

    python experiments/standin_camera.py --seeds 213 214 215 [--bus dynamixel] [--keep DIR]

The hidden camera is read here only (``testkit.standin_truth``), never by the calibration.
With ``--keep DIR`` each seed's result goes to ``DIR/camera-SEED.json`` and a seed measured
before is not measured again.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from calibration.camera import INTRINSIC_NAMES  # noqa: E402
from testkit.standin_owner import Owner, ServedRig, read_saved  # noqa: E402
from testkit.standin_truth import read_hidden  # noqa: E402


def one(bus: str, seed: int, work: Path) -> dict:
    hidden_path = work / f"camera-hidden-{seed}.json"
    t0 = time.monotonic()
    with ServedRig(bus, seed, hidden_path) as rig:
        owner = Owner(rig, f"s{seed}", work / f"cal-{seed}", rng_seed=seed)
        owner.calibrate_camera()
        saved = read_saved(owner.calibration_dir, owner.rig_id, "camera")
    k = read_hidden(hidden_path).camera.camera_matrix
    hidden = dict(zip(INTRINSIC_NAMES, (k[0, 0], k[1, 1], k[0, 2], k[1, 2]), strict=True))
    m = saved["camera_matrix"]
    fitted = dict(zip(INTRINSIC_NAMES, (m[0][0], m[1][1], m[0][2], m[1][2]), strict=True))
    out: dict = {"seed": seed, "bus": bus, "wall_s": round(time.monotonic() - t0, 1)}
    out["n_views"] = saved["n_views"]
    for n in INTRINSIC_NAMES:
        lo, hi = saved["intervals_95"][n]
        sd = saved["std_px"][n]
        out[n] = {
            "hidden": float(hidden[n]),
            "fitted": float(fitted[n]),
            "sd": float(sd),
            "error_sd": (fitted[n] - hidden[n]) / sd if sd > 0 else float("inf"),
            "interval": [lo, hi],
            "covered": bool(lo <= hidden[n] <= hi),
        }
    return out


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seeds", type=int, nargs="+", required=True)
    p.add_argument("--bus", default="dynamixel", choices=["dynamixel", "canopen"])
    p.add_argument("--keep", type=Path, default=None)
    args = p.parse_args()
    results = []
    with tempfile.TemporaryDirectory(prefix="standin-camera-") as scratch:
        work = Path(args.keep or scratch)
        work.mkdir(parents=True, exist_ok=True)
        for seed in args.seeds:
            kept = work / f"camera-{seed}.json"
            if kept.exists():
                results.append(json.loads(kept.read_text()))
                continue
            r = one(args.bus, seed, work)
            kept.write_text(json.dumps(r, indent=2))
            results.append(r)
    print("| stand-in | " + " | ".join(INTRINSIC_NAMES) + " |")
    print("|---|" + "---|" * len(INTRINSIC_NAMES))
    for r in results:
        cells = [
            f"{r[n]['fitted'] - r[n]['hidden']:+.2f} px, sd {r[n]['sd']:.2f} "
            f"({r[n]['error_sd']:+.1f} sd){'' if r[n]['covered'] else ' (outside)'}"
            for n in INTRINSIC_NAMES
        ]
        print(f"| {r['seed']} ({r['n_views']} views) | " + " | ".join(cells) + " |")
    held = sum(r[n]["covered"] for r in results for n in INTRINSIC_NAMES)
    print(f"inside their 95 % intervals: {held} of {len(results) * len(INTRINSIC_NAMES)}")
    print(json.dumps(results))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
