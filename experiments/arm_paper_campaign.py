"""The paper's experiment on stand-in arms over a bus: RPE, RGE-EFR and goals in learned spaces,
each a run of the guide's commands (docs/real_arm.md, steps 8-10) typed by
``testkit.standin_owner.Owner`` on ``ergo twin serve --bus BUS --stand-in SEED``.

For each bus and stand-in: the guide's calibrations (joints, camera, arena; with the ``warm``
arm also ``ergo calibrate dynamics``), then the arms asked by ``--arms``:
- ``rpe``, ``rge-efr``: ``ergo explore --strategy rpe|rge-efr`` over the bus;
- ``sae-twin``: ``rge-sae`` with a model trained on the twin's images (``--twin-sae DIR``:
  ``ergo dataset outcomes``, ``ergo sae train``);
- ``sae-arm``: ``rge-sae`` with a model trained on this arm's own outcome images: its ``rpe``
  run's (``ergo dataset outcomes --run``, then ``ergo sae train --seeds --arm-sae-seeds``, the
  label-free selection); needs ``rpe`` first in ``--arms``;
- ``online``: ``rge-online`` switching at ``--online-bootstrap`` (300; the paper's 2000 on its
  longer runs);
- ``warm``: ``rge-sae`` with the twin-trained model, warmed by a run of it on the twin fitted to
  this arm (``--rig sim --rig-id sSEED``, ``--twin-episodes``; docs/warm_start.md);
- ``warm-efr``: ``rge-efr`` warmed by an ``rge-efr`` run on the fitted twin (the recipe of
  docs/warm_start.md), against the ``rge-efr`` arm from scratch.

Resumable: everything is kept under ``--out``; calibrations that exist are kept, a finished run
is not run again, an unfinished one is resumed (``--resume-or-new``), a safety stop is resumed
as the guide says (``--resumes``); a stand-in is served again from its seed (the same rig). Each
rig's wall times go to ``OUT/rows/BUS-SEED.json`` as it ends (added to an earlier call's), the
table of ball cells at ``--at``, read from the runs, to ``OUT/table.md``; ``--figure PNG`` draws
the ball cells against episodes, a panel per rig (the paper's layout), from the runs'
``metrics.csv`` (``--report-only``: the table and figure from what is there, serving nothing).

    # development (stand-ins 300-399, exploration seeds 0-99), a few episodes
    .venv/bin/python experiments/arm_paper_campaign.py --buses dynamixel --seeds 301 \\
        --episodes 20 --arms rpe rge-efr sae-twin sae-arm online --online-bootstrap 10 \\
        --twin-sae models/sae --out /tmp/arm-paper-dev
    # the final campaign: stand-ins 210-212 over Dynamixel, one over CANopen
    .venv/bin/python experiments/arm_paper_campaign.py --buses dynamixel --seeds 210 211 212 \\
        --episodes 600 --explore-seed 820 --twin-sae models/sae --arm-sae-seeds 820-823 \\
        --out runs/arm-paper --figure docs/img/arm_paper.png
    .venv/bin/python experiments/arm_paper_campaign.py --buses canopen --seeds 210 \\
        --arms rge-efr sae-twin --episodes 600 --explore-seed 820 --twin-sae models/sae \\
        --out runs/arm-paper
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # testkit/, not installed

from script_helpers import add_prior_context, prior_option, save_figure

from calibration.dynamics.excitation import REPEATS
from explore.runs.metrics import read_metrics
from explore.runs.store import RunStore, read_history
from testkit.standin_owner import Owner, ServedRig

ARMS = ("rpe", "rge-efr", "sae-twin", "sae-arm", "online", "warm", "warm-efr")
STRATEGY = {"rpe": "rpe", "rge-efr": "rge-efr", "sae-twin": "rge-sae", "sae-arm": "rge-sae",
            "online": "rge-online", "warm": "rge-sae", "warm-efr": "rge-efr"}  # fmt: skip
AT = (100, 300, 600)  # the checkpoints of the table (issue's)
DYNAMICS_BOUND_S = 3600.0  # as experiments/rehearse_real_arm.py
TRAIN_BOUND_S = 7200.0  # the arm's autoencoder, several seeds on 2 shared cores (a bound)


def stored(run: Path) -> int:
    """Episodes a run holds (0 for none)."""
    return len(read_history(run).records) if RunStore.is_run(run) else 0


def curve(run: Path) -> list[int]:
    """The run's ball cells after each episode (empty without metrics)."""
    path = run / "metrics.csv"
    return [int(c) for c in read_metrics(path)["ball_cells"]] if path.is_file() else []


def arm_model(owner: Owner, rpe: Path, work: Path, args: argparse.Namespace) -> Path:
    """The arm's own spatial autoencoder: its RPE run's outcome images, the label-free
    selection over ``--arm-sae-seeds`` (resumable: ``ergo sae train`` continues)."""
    data, model = work / "arm-outcomes.npz", work / "arm-sae"
    if not data.is_file():
        owner.run("dataset", "outcomes", "--run", str(rpe), "--out", str(data))
    if not (model / "sae.pt").is_file():
        owner.run("sae", "train", "--data", str(data), "--out", str(model), "--seeds",
                  args.arm_sae_seeds, "--device", "cpu", "--no-progress",
                  timeout=TRAIN_BOUND_S)  # fmt: skip
    return model


def warm_prior(owner: Owner, rig_id: str, work: Path, args: argparse.Namespace, arm: str) -> Path:
    """The fitted twin's run of ``arm``'s strategy (``warm``: rge-sae with the twin-trained
    model; ``warm-efr``: rge-efr), fitting the servos first."""
    if not (owner.calibration_dir / rig_id / "dynamics.json").is_file():
        owner.run("calibrate", "dynamics", "--rig-id", rig_id, *owner.rig.bus_flags(),
                  "--no-report", "--repeats", str(args.dynamics_repeats),
                  timeout=DYNAMICS_BOUND_S)  # fmt: skip
    twin = work / ("twin-warm" if arm == "warm" else f"twin-{arm}")
    model = ["--strategy-option", f"sae={args.twin_sae}"] if arm == "warm" else []
    if stored(twin) < args.twin_episodes:
        owner.run("explore", "--rig", "sim", "--rig-id", rig_id, "--strategy", STRATEGY[arm],
                  *model, "--episodes", str(args.twin_episodes), "--seed", str(args.twin_seed),
                  "--out", str(twin), "--resume-or-new", "--no-progress")  # fmt: skip
    return twin


def one_rig(bus: str, seed: int, args: argparse.Namespace) -> dict[str, object]:
    """Every arm on one served stand-in; its row."""
    work = args.out / f"{bus}-{seed}"
    work.mkdir(parents=True, exist_ok=True)
    rig_id, cal = f"s{seed}", work / "cal"
    row: dict[str, object] = {"bus": bus, "stand-in": seed}
    t0 = time.monotonic()
    with ServedRig(bus, seed, work / "hidden.json", log=work / "serve.log") as rig:
        owner = Owner(rig, rig_id, cal, rng_seed=seed)
        if not (cal / rig_id / "arena.json").is_file():
            owner.scan()
            owner.calibrate_joints()
            owner.calibrate_camera()
            owner.calibrate_arena()
        for arm in args.arms:
            run = work / f"{arm}-e{args.explore_seed}"
            extra = ["--resume-or-new", "--no-progress"]
            if arm in ("sae-twin", "warm"):
                extra += ["--strategy-option", f"sae={args.twin_sae}"]
            if arm == "sae-arm":
                rpe = work / f"rpe-e{args.explore_seed}"
                model = arm_model(owner, rpe, work, args)
                extra += ["--strategy-option", f"sae={model}"]
            if arm == "online":
                extra += ["--strategy-option", f"bootstrap={args.online_bootstrap}"]
            if arm in ("warm", "warm-efr"):
                extra += ["--warm-start", str(warm_prior(owner, rig_id, work, args, arm))]
                extra += prior_option(args)
            t = time.monotonic()
            if stored(run) < args.episodes:
                owner.explore(run, args.episodes, args.explore_seed, STRATEGY[arm], extra,
                              resumes=args.resumes)  # fmt: skip
            row[f"{arm} s"] = round(time.monotonic() - t, 1)
        row["stops resumed"] = len(owner.stops)
    row["total s"] = round(time.monotonic() - t0, 1)
    return row


def rig_folders(args: argparse.Namespace) -> list[Path]:
    """The rig folders under OUT (BUS-SEED, with calibrations)."""
    return sorted(p for p in args.out.iterdir() if (p / "cal").is_dir())


def table(args: argparse.Namespace) -> str:
    """Ball cells at each checkpoint, read from the runs' ``metrics.csv``: an arm per column
    group (those any rig has), a rig per row; a blank where a run is shorter."""
    rigs = rig_folders(args)
    arms = [a for a in ARMS if any((r / f"{a}-e{args.explore_seed}").is_dir() for r in rigs)]
    head = ["rig", *(f"{a} @{n}" for a in arms for n in args.at)]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for rig in rigs:
        cells = {a: curve(rig / f"{a}-e{args.explore_seed}") for a in arms}
        values = [cells[a][n - 1] if n <= len(cells[a]) else "" for a in arms for n in args.at]
        lines.append("| " + " | ".join(map(str, [rig.name, *values])) + " |")
    return "\n".join(lines)


def figure(args: argparse.Namespace) -> None:
    """Ball cells against episodes, a panel per rig folder under OUT, a line per arm."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rigs = rig_folders(args)
    fig, axes = plt.subplots(1, max(len(rigs), 1), figsize=(4.2 * max(len(rigs), 1), 3.6),
                             squeeze=False)  # fmt: skip
    for ax, rig in zip(axes[0], rigs, strict=False):
        for arm in ARMS:
            cells = curve(rig / f"{arm}-e{args.explore_seed}")
            if cells:
                ax.plot(range(1, len(cells) + 1), cells, label=arm, color=f"C{ARMS.index(arm)}")
        ax.set_title(rig.name, fontsize=9)
        ax.set_xlabel("episodes")
        ax.set_ylabel("ball cells (30 x 30)")
        ax.legend(fontsize=7)
    fig.tight_layout()
    save_figure(fig, args.figure)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--buses", nargs="+", choices=("dynamixel", "canopen"), default=["dynamixel"])
    p.add_argument("--seeds", nargs="+", type=int, default=[], help="stand-in seeds")
    p.add_argument("--arms", nargs="+", choices=ARMS, default=list(ARMS))
    p.add_argument("--episodes", type=int, default=600, help="episodes of each bus run")
    p.add_argument("--at", type=lambda t: tuple(int(x) for x in t.split(",")), default=AT,
                   help="the table's checkpoints (default 100,300,600)")  # fmt: skip
    p.add_argument("--explore-seed", type=int, default=0)
    p.add_argument("--twin-sae", type=Path, help="the twin-trained autoencoder (sae-twin, warm)")
    p.add_argument(
        "--arm-sae-seeds",
        default="0-3",
        help="training seeds of the arm's model (0-3: development; final: 820-823)",
    )
    p.add_argument("--online-bootstrap", type=int, default=300, help="rge-online's switch")
    p.add_argument("--twin-episodes", type=int, default=1000, help="the warm arm's twin run")
    p.add_argument("--twin-seed", type=int, default=0)
    add_prior_context(p)
    p.add_argument(
        "--dynamics-repeats", type=int, default=REPEATS,
        help=f"ergo calibrate dynamics --repeats (default {REPEATS}; the results pages: 1)",
    )  # fmt: skip
    p.add_argument("--resumes", type=int, default=5, help="safety stops resumed, as the guide says")
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--figure", type=Path, default=None)
    p.add_argument("--report-only", action="store_true", help="the table and figure only")
    args = p.parse_args()
    if {"sae-twin", "warm"} & set(args.arms) and args.twin_sae is None and not args.report_only:
        p.error("the sae-twin and warm arms need --twin-sae DIR")
    if "sae-arm" in args.arms and "rpe" not in args.arms and not args.report_only:
        p.error("the sae-arm arm trains on the rpe run's images: put rpe first in --arms")
    (args.out / "rows").mkdir(parents=True, exist_ok=True)
    if not args.report_only:
        for bus in args.buses:
            for seed in args.seeds:
                path = args.out / "rows" / f"{bus}-{seed}.json"
                before = json.loads(path.read_text()) if path.is_file() else {}
                row = {**before, **one_rig(bus, seed, args)}  # another call's arms kept
                path.write_text(json.dumps(row, indent=2))
                print(json.dumps(row), flush=True)
    (args.out / "table.md").write_text(table(args) + "\n")
    print(table(args))
    if args.figure is not None:
        figure(args)


if __name__ == "__main__":
    main()
