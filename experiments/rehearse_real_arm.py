"""The owner's guide (docs/real_arm.md) rehearsed on stand-in rigs the software has never seen,
and what each calibration recovered against the stand-in's hidden parameters.

For each bus and seed: ``ergo twin serve --bus BUS --stand-in SEED``, then the guide's
commands in order, typed by ``testkit.standin_owner.Owner`` (its hands move the limp joints and
hold the chessboard): ``ergo bus scan``, ``ergo calibrate joints``, ``ergo calibrate camera``
(live views), ``ergo calibrate arena``, ``ergo calibrate show``, ``ergo explore`` (rge-efr).
Prints, per rig: the largest joint offset error (deg) and whether every direction is right,
the focal lengths' and principal point's errors (% and px), the ball's position from the arena
calibration against the truth (mm), the exploration's ball cells and the share of episodes in
which the camera tracked the ball; with ``--compare``, the same strategy and seed on the twin
in one process (``--rig sim``) and the ratio of ball cells. With ``--dynamics`` (issue 28), on
the same served stand-in after its exploration, ``ergo calibrate dynamics`` (the guide's
optional step, docs/dynamics.md); with ``--compare`` too, the same exploration in one process
on the fitted twin (``--rig sim --rig-id ID``) and on the twin with the stand-in's hidden servos
(written as a dynamics.json of another rig id: bench only).

    .venv/bin/python experiments/rehearse_real_arm.py --buses dynamixel canopen --seeds 31 32 33 \\
        --episodes 20
    .venv/bin/python experiments/rehearse_real_arm.py --buses dynamixel --seeds 31 --episodes 300 \\
        --compare
    .venv/bin/python experiments/rehearse_real_arm.py --buses dynamixel --seeds 81 --episodes 300 \\
        --compare --dynamics

Bounds (issue 27): offsets within 0.5 deg, directions all right; focal length within 1 % and
principal point within 3 px; at 300 episodes at least 0.8x the ball cells of the same seed in
one process. The figures are measured, not asserted (tests/system/test_guide.py asserts them
on one seed per bus).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from calibration.dynamics.excitation import REPEATS
from explore.runs.layout import METRICS_FILE
from explore.runs.store import read_history

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # testkit/, not installed
from testkit.standin_owner import Owner, ServedRig, read_saved
from testkit.standin_truth import arena_error_mm, camera_errors, joint_errors, read_hidden

# ``ergo calibrate dynamics`` over a bus, s, against hangs: 107 s of recording and a fit that
# took 180-330 s on 2 shared cores (docs/results_dynamics.md); with one repeat, a run over
# 900 s was measured at load 10.
DYNAMICS_BOUND_S = 3600.0


def ball_error_mm(step_stdout: str, hidden) -> float:
    """Distance between the ball the arena calibration located ("-> arena (X, Y) mm") and the
    stand-in's hidden start position, mm (the arm may have pushed it since)."""
    text = step_stdout.split("-> arena (", 1)[1].split(")", 1)[0]
    xy = np.array([float(v) for v in text.split(",")]) / 1000.0
    return float(np.linalg.norm(xy - np.asarray(hidden.ball_xy, float)) * 1000.0)


def run_summary(run: Path) -> tuple[int, float, float]:
    """(ball cells reached, share of episodes whose ball was tracked, share that moved it)."""
    history = read_history(run)
    records = history.records
    tracked = np.mean([bool(np.isfinite(r.ball).all()) for r in records]) if records else 0.0
    moved = np.mean([bool(r.ball_moved) for r in records]) if records else 0.0
    lines = (run / METRICS_FILE).read_text().strip().splitlines()
    cells = int(lines[-1].split(",")[lines[0].split(",").index("ball_cells")])
    return cells, float(tracked), float(moved)


def in_process_cells(
    out: Path,
    episodes: int,
    seed: int,
    strategy: str,
    rig_id: str | None = None,
    calibration_dir: Path | None = None,
) -> tuple[int, float]:
    """The same exploration on the twin in one process: (ball cells, share moving the ball).
    With ``rig_id``, the twin's servos are that rig's dynamics.json in ``calibration_dir``."""
    cmd = [sys.executable, "-m", "explore.cli", "explore", "--rig", "sim", "--strategy", strategy]
    cmd += ["--episodes", str(episodes), "--seed", str(seed), "--out", str(out)]
    env = dict(os.environ)
    if rig_id is not None:
        cmd += ["--rig-id", rig_id]
        env["ERGO_CALIBRATION_DIR"] = str(calibration_dir)
    subprocess.run(cmd, check=True, capture_output=True, text=True, env=env)
    cells, _, moved = run_summary(out)
    return cells, moved


def rehearse(bus: str, seed: int, args: argparse.Namespace, tmp: Path) -> dict[str, object]:
    row: dict[str, object] = {"bus": bus, "seed": seed}
    hidden_path = tmp / f"{bus}-{seed}-h.json"
    t0 = time.monotonic()
    with ServedRig(bus, seed, hidden_path) as rig:
        hidden = read_hidden(hidden_path)
        owner = Owner(rig, f"s{seed}", tmp / f"cal-{bus}", rng_seed=seed, log=args.log)

        def saved(kind: str) -> dict:
            return read_saved(owner.calibration_dir, owner.rig_id, kind)

        run = tmp / f"run-{bus}-{seed}"
        if args.reuse and (run / "run.json").is_file():  # done before: its figures only
            row["reused"] = str(run)
            row["cells"], row["tracked"], row["moved"] = run_summary(run)
        else:
            scan = owner.scan()
            row["servos"] = sum(
                1 for line in scan.stdout.splitlines() if line.strip()[:1].isdigit()
            )
            t = time.monotonic()
            owner.calibrate_joints()
            row["joints s"] = time.monotonic() - t
            row["limp after joints"] = not any(owner.torque_read_back())
            err, row["directions"] = joint_errors(hidden, saved("joints"))
            row["offset err deg"] = float(err.max())
            t = time.monotonic()
            owner.calibrate_camera()
            row["camera s"] = time.monotonic() - t
            cam = camera_errors(hidden, saved("camera"))
            row["fx %"], row["fy %"] = 100 * cam["fx"], 100 * cam["fy"]
            row["cx px"], row["cy px"] = cam["cx_px"], cam["cy_px"]
            arena = owner.calibrate_arena()
            row["arena err mm"] = arena_error_mm(hidden, saved("arena"))
            row["ball err mm"] = ball_error_mm(arena.stdout, hidden)
            owner.show()
            t = time.monotonic()
            owner.explore(
                run, args.episodes, args.explore_seed, args.strategy, resumes=args.resumes
            )
            row["limp after explore"] = not any(owner.torque_read_back())
            row["stops resumed"] = len(owner.stops)
            for stop in owner.stops:
                print(f"  {bus} {seed}: {stop}", flush=True)
            row["explore s"] = time.monotonic() - t
            row["cells"], row["tracked"], row["moved"] = run_summary(run)
        if args.faults:  # Ctrl-C in the middle of a run; a bus fault ends in the explore above
            stopped = owner.interrupt_explore(tmp / f"run-{bus}-{seed}-ctrl-c", after_s=20.0)
            row["ctrl-c rc"] = stopped.rc
            row["limp after ctrl-c"] = not any(owner.torque_read_back())
        if args.dynamics:
            t = time.monotonic()
            fit = owner.run(
                "calibrate", "dynamics", "--rig-id", owner.rig_id, *rig.bus_flags(),
                "--repeats", str(args.dynamics_repeats), check=False, timeout=DYNAMICS_BOUND_S,
            )  # fmt: skip
            row["dynamics s"] = time.monotonic() - t
            row["dynamics rc"] = fit.rc
            row["dynamics"] = next((x for x in fit.stdout.splitlines() if "held-out" in x), "")
    row["total s"] = time.monotonic() - t0
    if args.compare:
        t = time.monotonic()
        cells, moved = in_process_cells(
            tmp / f"sim-{seed}", args.episodes, args.explore_seed, args.strategy
        )
        row["cells in process"] = cells
        row["moved in process"] = moved
        row["cells ratio"] = row["cells"] / max(cells, 1)
        row["in process s"] = time.monotonic() - t
        if args.dynamics and row["dynamics rc"] == 0:
            cal = owner.calibration_dir
            write_hidden_servos(cal, owner.rig_id, f"{owner.rig_id}-hidden", hidden.servos)
            for label, rig_id in (("fitted", owner.rig_id), ("hidden", f"{owner.rig_id}-hidden")):
                cells, moved = in_process_cells(
                    tmp / f"sim-{seed}-{label}", args.episodes, args.explore_seed,
                    args.strategy, rig_id, cal,
                )  # fmt: skip
                row[f"cells {label} twin"], row[f"moved {label} twin"] = cells, moved
    return row


def write_hidden_servos(cal: Path, fitted_rig: str, rig_id: str, servos) -> None:
    """The stand-in's hidden servos as a dynamics.json of ``rig_id`` (bench only: the fitted
    rig's file with its ``servos`` replaced, so the twin in one process can be built with
    them through ``--rig-id``)."""
    doc = json.loads((cal / fitted_rig / "dynamics.json").read_text())
    doc["rig_id"] = rig_id
    doc["data"]["servos"] = servos.to_dict()
    doc["data"]["notes"] = ["the stand-in's hidden servos (experiments/rehearse_real_arm.py)"]
    (cal / rig_id).mkdir(parents=True, exist_ok=True)
    (cal / rig_id / "dynamics.json").write_text(json.dumps(doc, indent=2) + "\n")


def fmt(value: object) -> str:
    if isinstance(value, bool):
        return "all right" if value else "WRONG"
    if isinstance(value, float):
        return f"{value:+.3f}" if abs(value) < 10 else f"{value:.0f}"
    return str(value)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--buses", nargs="+", default=["dynamixel", "canopen"])
    p.add_argument("--seeds", nargs="+", type=int, default=[31, 32, 33])
    p.add_argument("--episodes", type=int, default=20, help="episodes of the check run")
    p.add_argument("--explore-seed", type=int, default=0)
    p.add_argument("--strategy", default="rge-efr")
    p.add_argument("--resumes", type=int, default=3, help="safety stops resumed, as the guide says")
    p.add_argument(
        "--faults", action="store_true", help="also stop a run with Ctrl-C; torque read back"
    )
    p.add_argument("--compare", action="store_true", help="also in one process, same seed")
    p.add_argument(
        "--dynamics",
        action="store_true",
        help="also ergo calibrate dynamics on the served rig (with --compare: on its twin too)",
    )
    p.add_argument(
        "--dynamics-repeats", type=int, default=REPEATS,
        help=f"with --dynamics: ergo calibrate dynamics --repeats (default {REPEATS})",
    )  # fmt: skip
    p.add_argument("--out", type=Path, default=None, help="keep the folders here")
    p.add_argument(
        "--reuse",
        action="store_true",
        help="with --out: a rig whose run folder exists keeps its calibrations and run (only "
        "the steps after the exploration are done again)",
    )
    p.add_argument("--verbose", action="store_true", help="print every command's output")
    args = p.parse_args()
    args.log = print if args.verbose else None
    tmp = args.out or Path(tempfile.mkdtemp(prefix="ergo-rehearse-"))
    tmp.mkdir(parents=True, exist_ok=True)
    rows = []
    for bus in args.buses:
        for seed in args.seeds:
            row = rehearse(bus, seed, args, tmp)
            rows.append(row)
            (tmp / f"row-{bus}-{seed}.json").write_text(json.dumps(row, indent=2, default=str))
            print("  ".join(f"{k}: {fmt(v)}" for k, v in row.items()), flush=True)
    rows = [r for r in rows if "offset err deg" in r]  # --reuse: no calibration this time
    if not rows:
        return
    worst = max(float(r["offset err deg"]) for r in rows)
    focal = max(max(abs(float(r["fx %"])), abs(float(r["fy %"]))) for r in rows)
    centre = max(math.hypot(float(r["cx px"]), float(r["cy px"])) for r in rows)
    arena = max(float(r["arena err mm"]) for r in rows)
    print(
        f"over {len(rows)} rigs: offsets within {worst:.3f} deg (bound 0.5), directions "
        f"{'all right' if all(r['directions'] for r in rows) else 'NOT all right'}; focal "
        f"within {focal:.3f} % (bound 1), principal point within {centre:.2f} px (bound 3); "
        f"arena floor within {arena:.2f} mm"
    )
    if args.compare:
        ratios = ", ".join(f"{r['bus']} {r['seed']}: {float(r['cells ratio']):.2f}" for r in rows)
        print(f"ball cells over the bus / in one process: {ratios} (bound 0.8)")


if __name__ == "__main__":
    main()
