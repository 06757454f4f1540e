"""An arm's exploration from scratch against warmed by its twin (docs/warm_start.md), on stand-in
rigs served over a bus (``ergo twin serve --bus BUS --stand-in SEED``), with the guide's
commands (docs/real_arm.md) typed by ``testkit.standin_owner.Owner``.

For each bus and stand-in: the calibrations of the guide (joints, camera, arena), then, as
asked by ``--arms``:
- ``scratch``: ``ergo explore --rig BUS --rig-id sSEED ... --episodes N`` over the bus;
- ``nominal``: a twin run in one process on the nominal twin (``--rig sim``, the recipe's
  strategy and episodes), then the same bus run with ``--warm-start`` it;
- ``fitted``: ``ergo calibrate dynamics`` over the bus first (docs/dynamics.md), a twin run on
  the fitted twin (``--rig sim --rig-id sSEED``), then the bus run warmed by it.
``--buses hidden`` instead: the "arm" is the twin in one process given the stand-in's hidden
servos (bench only; its ball starts where the twin's does), scratch against nominal-warm, in
seconds. Every part's wall time is kept, with each run's ball cells, the share of episodes
that moved the ball and, for the warmed runs, the reality gap's line (``ergo report``).

Resumable: everything is kept under ``--out``; a bus or a stand-in whose calibrations exist
keeps them, a finished run is not run again, and an unfinished one is resumed
(``--resume-or-new``); a served stand-in is served again from its seed (the same rig). Each
row is written to ``OUT/rows/BUS-SEED-eEXPLORE_SEED.json`` as it ends, and the table to
``OUT/table.md``.

    # development (stand-ins 300-399, exploration seeds 0-99)
    .venv/bin/python experiments/warm_start_campaign.py --buses dynamixel --seeds 301 \\
        --arms scratch nominal --episodes 60 --out /tmp/warm-dev
    # the final campaign (docs/warm_start.md): 3 stand-ins x 2 buses x 3 arms x 300 episodes
    .venv/bin/python experiments/warm_start_campaign.py --buses dynamixel canopen \\
        --seeds 200 201 202 --arms scratch nominal fitted --episodes 300 --out runs/warm-final
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # testkit/, not installed

from script_helpers import add_prior_context, prior_option

from calibration.dynamics.excitation import REPEATS
from explore.runs.layout import METRICS_FILE
from explore.runs.store import RunStore, read_history
from testkit.standin_owner import Owner, ServedRig

ERGO = [sys.executable, "-m", "explore.cli"]
TWIN_STRATEGY = "rge-efr"
TWIN_EPISODES = 1000  # the recipe's (docs/warm_start.md)
ARMS = ("scratch", "nominal", "fitted")
DYNAMICS_BOUND_S = 3600.0  # as experiments/rehearse_real_arm.py


def cells_of(run: Path) -> tuple[int, int, float]:
    """(episodes, ball cells after the last, share of episodes that moved the ball)."""
    records = read_history(run).records
    lines = (run / METRICS_FILE).read_text().strip().splitlines()
    cells = int(lines[-1].split(",")[lines[0].split(",").index("ball_cells")])
    moved = sum(bool(r.ball_moved) for r in records) / max(len(records), 1)
    return len(records), cells, moved


def finished(run: Path, episodes: int) -> bool:
    return RunStore.is_run(run) and len(read_history(run).records) >= episodes


def twin_run(out: Path, args: argparse.Namespace, rig_id: str | None, cal: Path) -> float:
    """The twin run of the recipe in one process (resumed if unfinished); its wall time, s."""
    t = time.monotonic()
    if not finished(out, args.twin_episodes):
        cmd = [*ERGO, "explore", "--rig", "sim", "--strategy", args.strategy,
               "--episodes", str(args.twin_episodes), "--seed", str(args.twin_seed),
               "--out", str(out), "--resume-or-new", "--no-progress"]  # fmt: skip
        env = None
        if rig_id is not None:
            cmd += ["--rig-id", rig_id]
            env = {**os.environ, "ERGO_CALIBRATION_DIR": str(cal)}
        subprocess.run(cmd, check=True, capture_output=True, text=True, env=env)
    return time.monotonic() - t


def gap_line(run: Path) -> str:
    done = subprocess.run([*ERGO, "report", str(run)], capture_output=True, text=True)
    return next((x for x in done.stdout.splitlines() if x.startswith("reality gap:")), "")


def in_process(seed: int, args: argparse.Namespace, work: Path) -> dict[str, object]:
    """``--buses hidden``: the "arm" is the twin in one process given the stand-in's hidden
    servos (written as rig sSEED-hidden's dynamics.json: bench only), its ball where the twin's
    is; the nominal arm only (a fit needs a bus)."""
    from calibration import store
    from sim.standin.hidden import draw_hidden

    row: dict[str, object] = {"bus": "hidden", "stand-in": seed}
    rig_id, cal = f"s{seed}-hidden", work / f"cal-hidden-{seed}"
    if not (cal / rig_id / "dynamics.json").is_file():
        payload = {
            "servos": draw_hidden(seed).servos.to_dict(),
            "recording": {"path": "hidden", "sha256": "0" * 64},
            "held_out_rms_rad": {"nominal": 0.0, "fitted": 0.0},
        }
        store.save("dynamics", rig_id, payload, cal)
    env = {**os.environ, "ERGO_CALIBRATION_DIR": str(cal)}
    for arm in args.arms:
        if arm == "fitted":
            continue
        extra = []
        if arm == "nominal":
            twin = work / f"twin-nominal-hidden-{seed}"
            row["nominal twin s"] = round(twin_run(twin, args, None, cal), 1)
            extra = ["--warm-start", str(twin), *prior_option(args)]
        run = work / f"run-{arm}-hidden-{seed}-e{args.explore_seed}"
        t = time.monotonic()
        if not finished(run, args.episodes):
            subprocess.run(
                [*ERGO, "explore", "--rig", "sim", "--rig-id", rig_id, "--strategy",
                 args.strategy, "--episodes", str(args.episodes), "--seed",
                 str(args.explore_seed), "--out", str(run), "--resume-or-new", "--no-progress",
                 *extra], check=True, capture_output=True, text=True, env=env,
            )  # fmt: skip
        row[f"{arm} s"] = round(time.monotonic() - t, 1)
        n, cells, moved = cells_of(run)
        row[f"{arm} cells"], row[f"{arm} moved"], row[f"{arm} episodes"] = cells, round(moved, 3), n
        if arm != "scratch":
            row[f"{arm} gap"] = gap_line(run)
    return row


def one_rig(bus: str, seed: int, args: argparse.Namespace, work: Path) -> dict[str, object]:
    if bus == "hidden":
        return in_process(seed, args, work)
    row: dict[str, object] = {"bus": bus, "stand-in": seed}
    rig_id = f"s{seed}"
    cal = work / f"cal-{bus}-{seed}"
    t0 = time.monotonic()
    with ServedRig(bus, seed, work / f"hidden-{bus}-{seed}.json") as rig:
        owner = Owner(rig, rig_id, cal, rng_seed=seed)
        if not (cal / rig_id / "arena.json").is_file():
            t = time.monotonic()
            owner.scan()
            owner.calibrate_joints()
            owner.calibrate_camera()
            owner.calibrate_arena()
            row["calibrations s"] = round(time.monotonic() - t, 1)
        if "fitted" in args.arms and not (cal / rig_id / "dynamics.json").is_file():
            t = time.monotonic()
            owner.run("calibrate", "dynamics", "--rig-id", rig_id, *rig.bus_flags(),
                      "--no-report", "--repeats", str(args.dynamics_repeats),
                      timeout=DYNAMICS_BOUND_S)  # fmt: skip
            row["dynamics s"] = round(time.monotonic() - t, 1)
        for arm in args.arms:
            extra = ["--resume-or-new", "--no-progress"]
            if arm != "scratch":
                twin = work / f"twin-{arm}-{bus}-{seed}"
                row[f"{arm} twin s"] = round(
                    twin_run(twin, args, rig_id if arm == "fitted" else None, cal), 1
                )
                extra += ["--warm-start", str(twin), *prior_option(args)]
            run = work / f"run-{arm}-{bus}-{seed}-e{args.explore_seed}"
            t = time.monotonic()
            if not finished(run, args.episodes):
                owner.explore(run, args.episodes, args.explore_seed, args.strategy, extra,
                              resumes=args.resumes)  # fmt: skip
            row[f"{arm} s"] = round(time.monotonic() - t, 1)
            n, cells, moved = cells_of(run)
            row[f"{arm} cells"], row[f"{arm} moved"] = cells, round(moved, 3)
            row[f"{arm} episodes"] = n
            if arm != "scratch":
                row[f"{arm} gap"] = gap_line(run)
        row["stops resumed"] = len(owner.stops)
    row["total s"] = round(time.monotonic() - t0, 1)
    return row


def table(rows: list[dict[str, object]], arms: list[str]) -> str:
    head = ["bus", "stand-in", *(f"{a} cells" for a in arms), *(f"{a} s" for a in arms)]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        lines.append("| " + " | ".join(str(r.get(h, "")) for h in head) + " |")
    return "\n".join(lines)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument(
        "--buses", nargs="+", choices=("dynamixel", "canopen", "hidden"),
        default=["dynamixel", "canopen"],
        help="hidden: the twin in one process given the stand-in's hidden servos (no bus)",
    )  # fmt: skip
    p.add_argument("--seeds", nargs="+", type=int, required=True, help="stand-in seeds")
    p.add_argument("--arms", nargs="+", choices=ARMS, default=list(ARMS))
    p.add_argument("--episodes", type=int, default=300, help="episodes of each bus run")
    p.add_argument("--explore-seed", type=int, default=0)
    add_prior_context(p)
    p.add_argument("--strategy", default=TWIN_STRATEGY)
    p.add_argument("--twin-episodes", type=int, default=TWIN_EPISODES)
    p.add_argument("--twin-seed", type=int, default=0)
    p.add_argument(
        "--dynamics-repeats", type=int, default=REPEATS,
        help=f"ergo calibrate dynamics --repeats (default {REPEATS}; docs/warm_start.md: 1)",
    )  # fmt: skip
    p.add_argument("--resumes", type=int, default=3, help="safety stops resumed, as the guide says")
    p.add_argument("--out", type=Path, required=True)
    args = p.parse_args()
    (args.out / "rows").mkdir(parents=True, exist_ok=True)
    rows = []
    for bus in args.buses:
        for seed in args.seeds:
            row = one_rig(bus, seed, args, args.out)
            rows.append(row)
            name = f"{bus}-{seed}-e{args.explore_seed}.json"
            (args.out / "rows" / name).write_text(json.dumps(row, indent=2))
            print(json.dumps(row), flush=True)
    (args.out / "table.md").write_text(table(rows, args.arms) + "\n")
    print(table(rows, args.arms))


if __name__ == "__main__":
    main()
