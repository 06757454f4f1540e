"""The ball tracker with the ball all around the arena's wall, on served stand-in rigs: misses
and their reasons, and errors against where the ball was put, with the outline fit
(``TrackerConfig.outline_fit``, the default) and without it (the enclosing-circle test alone).

Each stand-in is served over a bus (``ergo twin serve --stand-in SEED``) and calibrated as the
guide says (docs/real_arm.md: ``ergo calibrate camera``, then ``ergo calibrate arena``), typed by
``testkit.standin_owner.Owner``; its hands hold the arm at rest and put the ball down every
``--step`` degrees at each radius of ``--radii`` (from the ring's middle, 0.15 m, to touching the
wall, 0.17 m: the ball's centre is at most the wall's 0.20 m less its 0.03 m radius from the
base). Then the hands hold the arm over the ball (the tool tip hovering 1 cm above it, over its
centre and over each side) to check that an arm hiding part of the ball gives no wrong
position. The frames and the calibrations are kept in WORK/SEED; ``--reuse`` reads them
instead of serving.

    .venv/bin/python experiments/tracker_wall.py --seeds 301 321 329 --work runs/tracker_wall

Prints, per stand-in and in all: placements, misses (not seen) and their reasons, wrong
positions (seen more than ``WRONG_MM`` from where the ball was put), the error's median and
maximum, for both trackers; the occluded frames' outcomes; the arena calibration's own error
against the hidden camera (``testkit.standin_truth.arena_error_mm``), the floor under the
tracker's error.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # testkit/, not installed

from sim.standin.hands import HandsError
from testkit.standin_owner import Owner, ServedRig
from testkit.standin_truth import arena_error_mm, read_hidden
from testkit.standin_views import FRESH_FRAMES, SETTLE_WALL_S, hold_at_rest

RIG_ID = "standin"
WRONG_MM = 5.0  # a seen ball this far from where it was put is a wrong position (tests' bound)
# Where the tool tip hovers for the occlusion check: above the ball's top (0.06 m) by its own
# radius (13 mm, sim/models/ergo_jr.xml) and 1 cm more (chosen), over the ball's centre and
# 2 cm off it radially and sideways (chosen: the tool then hides a side of the ball).
HOVER_Z_M = 0.06 + 0.013 + 0.01
HOVER_OFFSETS_M = ((0.0, 0.0), (0.02, 0.0), (-0.02, 0.0), (0.0, 0.02), (0.0, -0.02))
OCCLUSION_ANGLES_DEG = (0, 45, 90, 135, 180, 225, 270, 315)
OCCLUSION_RADIUS_M = 0.16


def wall_places(step_deg: float, radii: list[float]) -> np.ndarray:
    """Ball centres every ``step_deg`` around the base at each radius: (n, 2) m."""
    angles = np.radians(np.arange(0.0, 360.0, step_deg))
    return np.array([(r * math.cos(a), r * math.sin(a)) for r in radii for a in angles])


def hover_poses() -> tuple[np.ndarray, list[dict[str, float]]]:
    """Ball places for the occlusion check, (n, 2) m, and the joint angles (rad) that put the
    tool tip over each (m4 and m6 at zero), solved on the nominal twin's kinematics; poses
    whose arm would touch the ball are left out."""
    import mujoco
    from scipy.optimize import least_squares

    from robot.spec import ergo_jr_spec
    from sim.twin import SCENE, Twin

    names = ergo_jr_spec().names
    free = [names.index(n) for n in ("m1", "m2", "m3", "m5")]
    twin = Twin(SCENE)
    places, poses = [], []
    try:
        ball = twin.model.geom("ball").id
        ball_body = twin.model.geom_bodyid[ball]
        for deg in OCCLUSION_ANGLES_DEG:
            a = math.radians(deg)
            radial, side = (
                np.array((math.cos(a), math.sin(a))),
                np.array((-math.sin(a), math.cos(a))),
            )
            centre = OCCLUSION_RADIUS_M * radial
            for dr, ds in HOVER_OFFSETS_M:
                tip = np.array([*(centre + dr * radial + ds * side), HOVER_Z_M])
                q = np.zeros(len(names))

                def residual(x: np.ndarray, q=q, tip=tip) -> np.ndarray:
                    q[free] = x
                    twin.data.qpos[twin._qpos_idx] = q
                    mujoco.mj_kinematics(twin.model, twin.data)
                    return twin.end_effector_position() - tip

                lo, hi = twin.model.jnt_range[free].T + np.array([[1e-3], [-1e-3]])
                # leaning forward towards the place, or backward with m1 turned half a turn
                starts = [(a, 1.0, 0.6, 0.6), (a + math.pi, -1.0, -0.6, -0.6)]
                fits = [
                    least_squares(residual, np.clip(np.array(x0), lo, hi), bounds=(lo, hi))
                    for x0 in ((math.remainder(s[0], 2 * math.pi), *s[1:]) for s in starts)
                ]
                fit = min(fits, key=lambda f: float(np.linalg.norm(f.fun)))
                if np.linalg.norm(fit.fun) > 1e-3:
                    continue
                residual(fit.x)
                twin.place_ball(tuple(centre))
                touching = any(  # the ball within 3 mm of a geom of the arm
                    ball in (c.geom1, c.geom2)
                    and twin.model.geom_bodyid[c.geom1 + c.geom2 - ball] not in (0, ball_body)
                    and c.dist < 0.003
                    for c in twin.data.contact[: twin.data.ncon]
                )
                if not touching:
                    places.append(centre)
                    poses.append({names[j]: float(q[j]) for j in free})
    finally:
        twin.close()
    return np.array(places), poses


def serve_and_look(seed: int, bus: str, work: Path, places: np.ndarray) -> dict[str, np.ndarray]:
    """Serve the stand-in, calibrate its camera and arena as the guide does, look at the ball
    at each place with the arm at rest, then with the arm hovering over it."""
    from vision.make_camera import make_camera

    hover_places, poses = hover_poses()
    with ServedRig(bus, seed, work / "hidden.json", log=work / "serve.log") as rig:
        owner = Owner(rig, RIG_ID, work / "cal", log=print, rng_seed=seed)
        owner.calibrate_camera()
        hold_at_rest(owner)
        owner.calibrate_arena()
        frames, hidden_frames = [], []
        with owner.hands() as hands, make_camera(rig.camera_url, files="live") as camera:

            def look() -> np.ndarray:
                time.sleep(SETTLE_WALL_S)
                for _ in range(FRESH_FRAMES):
                    camera.read()
                return camera.read().image

            t0 = time.monotonic()
            for xy in places:
                hands.place_ball((float(xy[0]), float(xy[1])))
                frames.append(look())
            print(f"stand-in {seed}: {len(places)} places in {time.monotonic() - t0:.0f} s")
            np.savez_compressed(work / "places.npz", places=places, frames=np.stack(frames))
            kept = []
            for xy, pose in zip(hover_places, poses, strict=True):
                # the ball out of the arm's way (across the arena) while the arm moves
                hands.place_ball((-0.15 * xy[0] / np.hypot(*xy), -0.15 * xy[1] / np.hypot(*xy)))
                try:
                    hands.move(pose)
                except HandsError as exc:  # a pose the stand-in's arm did not hold still
                    print(f"stand-in {seed}: hover pose left out: {exc}")
                    continue
                hands.place_ball((float(xy[0]), float(xy[1])))
                hidden_frames.append(look())
                kept.append(xy)
            hands.move({n: 0.0 for n in pose})
    return {
        "places": places,
        "frames": np.stack(frames),
        "hover_places": np.array(kept).reshape(-1, 2),
        "hover_frames": np.stack(hidden_frames),
    }


def track_all(tracker, frames: np.ndarray, places: np.ndarray) -> dict[str, Any]:
    """Each frame's outcome: ``reasons`` (``""`` when seen, else the reason's words without
    figures), ``errors`` against its place (mm, NaN when not seen), ``outline`` (whether the
    outline's circle gave the position); and the largest blob's measures where it is
    significant: ``circularity``, and its outline's circle (``radius`` over the expected one,
    ``fill``, ``outside``, ``arc``, and how far its centre lies from the place, ``fit_error``
    mm; NaN without one)."""
    from vision.rectify import pixels_to_arena

    keys = ("reasons", "errors", "outline", "circularity", "radius", "fill", "outside", "arc")
    out: dict[str, list] = {k: [] for k in (*keys, "fit_error")}
    for frame, xy in zip(frames, places, strict=True):
        obs = tracker.track(frame)
        if obs.seen and obs.xy is not None:
            out["reasons"].append("")
            out["errors"].append(float(np.hypot(*(np.asarray(obs.xy) - xy))) * 1000)
        else:
            out["reasons"].append((obs.reason or "not on the arena").split("(")[0].strip())
            out["errors"].append(np.nan)
        out["outline"].append(obs.outline is not None)
        blob = obs.blobs[0] if obs.blobs else None
        fit = tracker.outline(blob) if blob is not None else None
        expected = tracker.expected_radius_at(fit.centre) if fit is not None else None
        out["circularity"].append(blob.circularity if blob is not None else np.nan)
        out["radius"].append(fit.radius / expected if expected else np.nan)
        out["fill"].append(fit.fill if fit is not None else np.nan)
        out["outside"].append(fit.outside if fit is not None else np.nan)
        out["arc"].append(fit.arc_deg if fit is not None else np.nan)
        if fit is None:
            out["fit_error"].append(np.nan)
        else:
            at = pixels_to_arena(tracker.arena, np.array(fit.centre), tracker.config.ball_radius_m)
            out["fit_error"].append(float(np.hypot(*(at[0] - xy))) * 1000)
    return {k: (v if k == "reasons" else np.array(v)) for k, v in out.items()}


def span(result: dict[str, Any], sel: np.ndarray, key: str) -> str:
    """The range of ``result[key]`` over the frames ``sel`` (bool), NaNs left out."""
    v = result[key][sel]
    v = v[np.isfinite(v)]
    return f"{v.min():.3f}-{v.max():.3f}" if len(v) else "-"


def joined(results: list[dict[str, Any]]) -> dict[str, Any]:
    """Several ``track_all`` results as one."""
    return {
        k: [x for r in results for x in r[k]]
        if k == "reasons"
        else np.concatenate([r[k] for r in results])
        for k in results[0]
    }


def summary(name: str, result: dict[str, Any]) -> str:
    """One table row: frames, misses, wrong positions, the error, the misses' reasons."""
    reasons, err = result["reasons"], result["errors"]
    misses = Counter(r for r in reasons if r)
    wrong = int(np.sum(err > WRONG_MM))
    seen = err[np.isfinite(err)]
    why = "; ".join(f"{k}: {v}" for k, v in misses.most_common()) or "-"
    stats = f"{np.median(seen):.1f}, {seen.max():.1f}" if len(seen) else "-"
    by_outline = err[result["outline"]]
    rescued = f"{len(by_outline)}" + (f" (max {by_outline.max():.1f})" if len(by_outline) else "")
    return (
        f"| {name} | {len(reasons)} | {sum(misses.values())} | {wrong} | {stats} | {rescued} "
        f"| {why} |"
    )


HEADER = (
    "| {what} | tracker | frames | misses | wrong (> 5 mm) | error median, max (mm) | "
    "by the outline (its error max, mm) | misses' reasons |\n|---|---|---|---|---|---|---|---|"
)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[301, 321, 329])
    ap.add_argument("--bus", choices=("dynamixel", "canopen"), default="dynamixel")
    ap.add_argument("--step", type=float, default=5.0, help="degrees between places (5)")
    ap.add_argument("--radii", type=float, nargs="+", default=[0.15, 0.16, 0.165, 0.17], help="m")
    ap.add_argument("--work", type=Path, required=True, help="a folder per stand-in in it")
    ap.add_argument("--reuse", action="store_true", help="read WORK/SEED/views.npz")
    args = ap.parse_args()

    from dataclasses import replace

    from calibration.store import load_arena_file
    from vision.rectify import ArenaModel
    from vision.tracker import BallTracker, tracker_config_from_arena

    trackers = {"before": False, "after": True}  # TrackerConfig.outline_fit
    walls: dict[str, list[dict[str, Any]]] = {name: [] for name in trackers}
    hovers: dict[str, list[dict[str, Any]]] = {name: [] for name in trackers}
    radii: list[np.ndarray] = []
    print(HEADER.format(what="stand-in (arena error)"))
    for seed in args.seeds:
        work = args.work / str(seed)
        work.mkdir(parents=True, exist_ok=True)
        saved = work / "views.npz"
        if args.reuse:
            with np.load(saved) as z:
                views = {k: z[k] for k in z.files}
        else:
            views = serve_and_look(seed, args.bus, work, wall_places(args.step, args.radii))
            np.savez_compressed(saved, **views)
        data = load_arena_file(work / "cal" / RIG_ID / "arena.json")
        arena = ArenaModel.from_dict(data)
        floor_mm = arena_error_mm(read_hidden(work / "hidden.json"), data)
        radii.append(np.hypot(*views["places"].T))
        for name, fit in trackers.items():
            tracker = BallTracker(replace(tracker_config_from_arena(data), outline_fit=fit), arena)
            walls[name].append(track_all(tracker, views["frames"], views["places"]))
            hovers[name].append(track_all(tracker, views["hover_frames"], views["hover_places"]))
            print(summary(f"{seed} ({floor_mm:.1f} mm) | {name}", walls[name][-1]))
    wall = {name: joined(results) for name, results in walls.items()}
    hover = {name: joined(results) for name, results in hovers.items()}
    for name in trackers:
        print(summary(f"all | {name}", wall[name]))
    r = np.concatenate(radii)
    print("\nmisses per radius:")
    for x in sorted(set(np.round(r, 4))):
        at = np.abs(r - x) < 1e-6
        counts = ", ".join(
            f"{name} {int(np.sum(at & ~np.isfinite(wall[name]['errors'])))}" for name in trackers
        )
        print(f"  {x:.3f} m ({int(at.sum())} places): {counts}")
    print("\nthe arm hovering over the ball (the tool tip 1 cm above it):")
    print(HEADER.format(what="all"))
    for name in trackers:
        print(summary(f"all | {name}", hover[name]))
    whole = wall["after"]["circularity"] >= tracker.config.min_circularity
    over = hover["after"]
    everything = joined([wall["after"], over])
    print("\nthe largest blob's outline circle (the tracker's outline_* gates):")
    for what, res, sel in (
        ("balls at rest, round blobs", wall["after"], whole),
        ("balls at rest, not round", wall["after"], ~whole),
        ("the arm over the ball", over, np.ones(len(over["fill"]), bool)),
        ("  of which the circle within 5 mm", over, over["fit_error"] <= WRONG_MM),
        ("circles more than 5 mm off (any frame)", everything, everything["fit_error"] > WRONG_MM),
    ):
        measures = ", ".join(
            f"{label} {span(res, sel, key)}"
            for label, key in (
                ("circularity", "circularity"),
                ("radius / expected", "radius"),
                ("fill", "fill"),
                ("outside", "outside"),
                ("arc (deg)", "arc"),
            )
        )
        print(f"  {what} ({int(sel.sum())}): {measures}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
