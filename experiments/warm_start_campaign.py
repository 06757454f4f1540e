"""An arm's exploration from scratch against warmed by its twin (docs/warm_start.md), on stand-in
rigs served over a bus (``ergo twin serve --bus BUS --stand-in SEED``), with the guide's
commands (docs/real_arm.md) typed by ``sim.standin.owner.Owner``.

For each bus and stand-in: the calibrations of the guide (joints, camera, arena), then, as
asked by ``--arms``:
- ``scratch``: ``ergo explore --rig BUS --rig-id sSEED ... --episodes N`` over the bus;
- ``nominal``: a twin run in one process on the nominal twin (``--rig sim``, the recipe's
  strategy and episodes), then the same bus run with ``--warm-start`` it;
- ``fitted``: ``ergo calibrate dynamics`` over the bus first (docs/dynamics.md), a twin run on
  the fitted twin (``--rig sim --rig-id sSEED``), then the bus run warmed by it.
Every part's wall time is kept, with each run's ball cells, the share of episodes that moved
the ball and, for the warmed runs, the reality gap's line (``ergo report``).

Resumable: everything is kept under ``--out``; a bus or a stand-in whose calibrations exist
keeps them, a finished run is not run again, and an unfinished one is resumed
(``--resume-or-new``); a served stand-in is served again from its seed (the same rig). Each
row is written to ``OUT/rows/BUS-SEED.json`` as it ends, and the table to ``OUT/table.md``.

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

from explore.runs.layout import METRICS_FILE
from explore.runs.store import RunStore, read_history
from sim.standin.owner import Owner, ServedRig

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


def one_rig(bus: str, seed: int, args: argparse.Namespace, work: Path) -> dict[str, object]:
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
                      "--no-report", timeout=DYNAMICS_BOUND_S)  # fmt: skip
            row["dynamics s"] = round(time.monotonic() - t, 1)
        for arm in args.arms:
            extra = ["--resume-or-new", "--no-progress"]
            if arm != "scratch":
                twin = work / f"twin-{arm}-{bus}-{seed}"
                row[f"{arm} twin s"] = round(
                    twin_run(twin, args, rig_id if arm == "fitted" else None, cal), 1
                )
                extra += ["--warm-start", str(twin)]
            run = work / f"run-{arm}-{bus}-{seed}"
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
    p.add_argument("--buses", nargs="+", default=["dynamixel", "canopen"])
    p.add_argument("--seeds", nargs="+", type=int, required=True, help="stand-in seeds")
    p.add_argument("--arms", nargs="+", choices=ARMS, default=list(ARMS))
    p.add_argument("--episodes", type=int, default=300, help="episodes of each bus run")
    p.add_argument("--explore-seed", type=int, default=0)
    p.add_argument("--strategy", default=TWIN_STRATEGY)
    p.add_argument("--twin-episodes", type=int, default=TWIN_EPISODES)
    p.add_argument("--twin-seed", type=int, default=0)
    p.add_argument("--resumes", type=int, default=3, help="safety stops resumed, as the guide says")
    p.add_argument("--out", type=Path, required=True)
    args = p.parse_args()
    (args.out / "rows").mkdir(parents=True, exist_ok=True)
    rows = []
    for bus in args.buses:
        for seed in args.seeds:
            row = one_rig(bus, seed, args, args.out)
            rows.append(row)
            (args.out / "rows" / f"{bus}-{seed}.json").write_text(json.dumps(row, indent=2))
            print(json.dumps(row), flush=True)
    (args.out / "table.md").write_text(table(rows, args.arms) + "\n")
    print(table(rows, args.arms))


if __name__ == "__main__":
    main()
