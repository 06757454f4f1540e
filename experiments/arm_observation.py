"""What a learned goal space sees on a physical rig, before and after the arena view: a served
stand-in's camera with the ball put at known places, the image made from each frame as a
physical rig made it (the frame's centre square) and as it makes it now (the frame mapped
through the rig's calibrations onto the twin's overhead view, ``vision.observation.
ArenaObservation``), beside the twin's own render of the same scene (the arm at rest, the ball
at the same place). Prints the pixel correlation of their median images and per scene, and how
far the ball lies from the twin's (px of the 64 px image); for scale, the twin's own render at 8
times the side, area averaged as the arena view is, against its 64 px render; writes the
figure.

The stand-in is calibrated as the guide says (docs/real_arm.md: ``ergo calibrate camera``, then
``ergo calibrate arena``), typed by ``testkit.standin_owner.Owner``, whose hands hold the arm at
rest and put the ball down (``testkit.standin_views``). With ``--run-episodes N``, also the
guide's joint calibration and an ``rpe`` run of N episodes over the bus, beside the twin's run
of the same strategy and seed in one process: the median of their outcome images, as the
observation a run records.

    .venv/bin/python experiments/arm_observation.py --seed 301 --work runs/arm_observation/301 \\
        --figure docs/img/arm_observation.png --run-episodes 20

The frames are kept in WORK/views.npz; ``--reuse`` reads them instead of serving the stand-in.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # testkit/, not installed
from script_helpers import save_figure

from testkit.standin_owner import Owner, ServedRig
from testkit.standin_views import (
    ball_centroid,
    hold_at_rest,
    look_at_places,
    median_image,
    pixel_correlation,
    twin_renders,
)

RIG_ID = "standin"
SIDE = 64  # the observation's side, px (vision.observation.OBSERVATION_SIZE)


def serve_and_look(args: argparse.Namespace, places: np.ndarray) -> dict[str, np.ndarray]:
    """Serve the stand-in, calibrate its camera and arena as the guide does, look at the ball
    at each place; with ``--run-episodes``, the joint calibration and a run over the bus."""
    work = args.work
    with ServedRig(args.bus, args.seed, work / "hidden.json", log=work / "serve.log") as rig:
        owner = Owner(rig, RIG_ID, work / "cal", log=print, rng_seed=args.seed)
        if args.run_episodes:
            owner.calibrate_joints()
        owner.calibrate_camera()
        hold_at_rest(owner)
        owner.calibrate_arena()
        frames = look_at_places(owner, places)
        if args.run_episodes:
            with owner.hands() as hands:
                hands.release()
            owner.explore(work / "arm-rpe", args.run_episodes, seed=0, strategy="rpe", resumes=3)
            owner.run(
                "explore", "--rig", "sim", "--strategy", "rpe", "--episodes",
                str(args.run_episodes), "--seed", "0", "--out", str(work / "twin-rpe"),
                "--no-progress",
            )  # fmt: skip
    return {"places": places, "frames": frames}


def run_images(run: Path) -> np.ndarray:
    from explore.runs.store import read_history

    return np.stack([r.image for r in read_history(run).records])


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seed", type=int, default=301, help="the stand-in (default 301)")
    ap.add_argument("--bus", choices=("dynamixel", "canopen"), default="dynamixel")
    ap.add_argument("--n", type=int, default=20, help="ball places (default 20)")
    ap.add_argument("--places-seed", type=int, default=0, help="where the ball is put")
    ap.add_argument("--work", type=Path, required=True, help="folder for the calibrations, frames")
    ap.add_argument("--figure", type=Path, default=None, help="the before/after figure (PNG)")
    ap.add_argument("--run-episodes", type=int, default=0, help="also an rpe run of N episodes")
    ap.add_argument("--reuse", action="store_true", help="read WORK/views.npz, serve nothing")
    args = ap.parse_args()
    import cv2

    from calibration.store import load_arena_file
    from explore.rigs.ball import locator_from_calibration, observer_from_calibration
    from explore.rigs.sim_dataset import ring_positions
    from vision.observation import square_observation

    args.work.mkdir(parents=True, exist_ok=True)
    saved = args.work / "views.npz"
    if args.reuse:
        with np.load(saved) as z:
            views = {k: z[k] for k in z.files}
    else:
        places = ring_positions(args.n, np.random.default_rng(args.places_seed))
        views = serve_and_look(args, places)
        np.savez_compressed(saved, **views)
    places, frames = views["places"], views["frames"]
    data = load_arena_file(args.work / "cal" / RIG_ID / "arena.json")
    observe, locate = observer_from_calibration(data), locator_from_calibration(data)
    before = np.stack([square_observation(f, SIDE) for f in frames])
    after = np.stack([observe(f, SIDE) for f in frames])
    twin = twin_renders(places, SIDE)
    tracked = np.stack([locate(f) for f in frames])

    print(f"stand-in {args.seed} over {args.bus}, {len(places)} ball places on the ring")
    print(
        "| image | median images' correlation with the twin's | per scene (median, min) | "
        "ball from the twin's, px (median, max) |"
    )
    print("|---|---|---|---|")
    rows = {}
    for name, images in (("centre square (before)", before), ("arena view (after)", after)):
        corr = pixel_correlation(median_image(images), median_image(twin))
        each = [pixel_correlation(a, b) for a, b in zip(images, twin, strict=True)]
        gap = [
            np.linalg.norm(ball_centroid(a) - ball_centroid(b))
            for a, b in zip(images, twin, strict=True)
        ]
        rows[name] = corr
        print(
            f"| {name} | {corr:.3f} | {np.median(each):.3f}, {np.min(each):.3f} | "
            f"{np.nanmedian(gap):.2f}, {np.nanmax(gap):.2f} |"
        )
    fine = twin_renders(places, SIDE * 8)  # the twin's own render, area averaged: a reference
    fine = np.stack([cv2.resize(f, (SIDE, SIDE), interpolation=cv2.INTER_AREA) for f in fine])
    print(
        f"| the twin at {SIDE * 8} px, area averaged (reference) | "
        f"{pixel_correlation(median_image(fine), median_image(twin)):.3f} | | |"
    )
    err = np.linalg.norm(tracked - places, axis=1) * 1000
    print(
        f"tracker against the places: median {np.nanmedian(err):.1f} mm, max "
        f"{np.nanmax(err):.1f} mm, seen {np.isfinite(err).sum()}/{len(err)}"
    )
    if args.run_episodes and (args.work / "arm-rpe").exists():
        arm, tw = run_images(args.work / "arm-rpe"), run_images(args.work / "twin-rpe")
        corr = pixel_correlation(median_image(arm), median_image(tw))
        print(
            f"rpe runs of {len(arm)} episodes, the arm over {args.bus} against the twin in one "
            f"process: median outcome images' correlation {corr:.3f}"
        )
    if args.figure is not None:
        figure(args.figure, before, after, twin, rows)
    return 0


def figure(path: Path, before, after, twin, corr: dict[str, float]) -> None:
    """Three scenes and the median images: the centre square, the arena view, the twin's."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    picks = [0, 1, 2]
    fig, axes = plt.subplots(len(picks) + 1, 3, figsize=(7.2, 2.4 * (len(picks) + 1)))
    titles = [
        f"centre square (before)\nmedian r = {corr['centre square (before)']:.2f}",
        f"arena view (after)\nmedian r = {corr['arena view (after)']:.2f}",
        "the twin's render",
    ]
    for col, images in enumerate((before, after, twin)):
        for row, i in enumerate(picks):
            axes[row, col].imshow(images[i][..., ::-1], interpolation="nearest")
        axes[-1, col].imshow(median_image(images)[..., ::-1], interpolation="nearest")
        axes[0, col].set_title(titles[col], fontsize=9)
    for row in range(len(picks)):
        axes[row, 0].set_ylabel(f"scene {picks[row] + 1}", fontsize=9)
    axes[-1, 0].set_ylabel("median of all", fontsize=9)
    for ax in axes.ravel():
        ax.set_xticks([])
        ax.set_yticks([])
    fig.tight_layout()
    save_figure(fig, path)


if __name__ == "__main__":
    raise SystemExit(main())
