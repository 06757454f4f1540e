"""The transfer of a twin-trained goal space to the arm, measured: on stand-ins whose camera saw
the ball put at known places (``experiments/arm_observation.py`` keeps the frames and the
calibrations in its WORK folder), a model trained on the twin's images encodes the arm's view of
each scene (the frame mapped onto the twin's view by the rig's calibrations, as a run observes
it: ``explore.rigs.ball.observer_from_calibration``) and the twin's render of the same scene.

Printed per stand-in and over all of them:
- the code gap: the distance between the two codes of a scene, over the spread of the twin
  dataset's codes (the root of the summed per-dimension variances): 0 is the same code, 1 is as
  far as two twin outcomes typically are;
- where a readout of the code puts the ball, against the tracker (the arm's ball position, as a
  run records it): an affine map from code to (x, y), fitted by least squares on the twin
  dataset's codes and ball positions only (``--data``, e.g. ``ergo dataset outcomes``); the
  error in cells of the 30 x 30 metric (13.3 mm a side over the +-0.2 m square): the distance
  over a cell's side, and the largest of the two cell-index differences (0: the same cell);
  median and 90th percentile;
- the same readout on the twin's code against the true place (what the readout itself loses),
  the tracker against the true place (mm), and a 10-nearest-neighbour readout (the mean ball of
  the 10 twin outcomes nearest in code: the goal space's own kind of inverse model) beside the
  affine one, and the affine readout of the code of the frame's centre square (the image a
  physical rig observed before the arena view) against the tracker.
With ``--markers``, also the code gap the arena's four markers alone make: the nominal served
twin (``ergo twin serve`` without ``--stand-in``: the twin's camera and lens, the markers on its
floor) against the committed twin, on the same scenes (the places of the first WORK folder).

Goal (issue 54): the affine readout of the arm's code within 1 cell of the tracker (median) and
2 cells at the 90th percentile.

    .venv/bin/python experiments/arm_transfer.py --model models/sae --data outcomes.npz \\
        runs/arm_observation/210 runs/arm_observation/211 runs/arm_observation/212 \\
        --figure docs/img/arm_transfer.png
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # testkit/, not installed
from script_helpers import save_figure

from testkit.standin_views import twin_renders

RIG_ID = "standin"  # the calibration's rig id in a WORK folder (arm_observation.py)
NEIGHBOURS = 10


def load_model(path: Path):
    """A spatial autoencoder or a VAE folder (``encode_bgr``: images -> codes)."""
    from vision.spatial_ae import is_sae_folder, load_sae
    from vision.vae import load_vae

    return load_sae(path) if is_sae_folder(path) else load_vae(path)


def affine_readout(codes: np.ndarray, xy: np.ndarray):
    """The least-squares affine map code (n, d) -> xy (n, 2), as a function."""
    a = np.hstack([codes, np.ones((len(codes), 1))])
    w, *_ = np.linalg.lstsq(a, xy, rcond=None)
    return lambda c: np.hstack([c, np.ones((len(c), 1))]) @ w


def neighbour_readout(codes: np.ndarray, xy: np.ndarray, k: int = NEIGHBOURS):
    """The mean position of the k nearest codes (Euclidean), as a function."""

    def read(c: np.ndarray) -> np.ndarray:
        d = np.linalg.norm(c[:, None, :] - codes[None, :, :], axis=2)
        return xy[np.argsort(d, axis=1)[:, :k]].mean(axis=1)

    return read


def cell_errors(pred: np.ndarray, truth: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(distance in cell sides, largest cell-index difference) per point, NaN where unknown."""
    from explore.rigs.arena import TWIN_ARENA
    from explore.runs.metrics import N_BINS

    h = TWIN_ARENA.ball_half_width
    side = 2 * h / N_BINS
    dist = np.linalg.norm(pred - truth, axis=1) / side

    def index(p: np.ndarray) -> np.ndarray:
        return np.clip(np.floor((p + h) / side), 0, N_BINS - 1)

    cheb = np.abs(index(pred) - index(truth)).max(axis=1)
    cheb[~np.isfinite(dist)] = np.nan
    return dist, cheb


def q(values: np.ndarray) -> str:
    """Median and 90th percentile of the finite values."""
    v = np.asarray(values, float)
    v = v[np.isfinite(v)]
    return f"{np.median(v):.2f} / {np.percentile(v, 90):.2f}" if len(v) else "-"


def measure(work: Path, model, affine, neighbours, spread: float) -> dict[str, np.ndarray]:
    """The codes and readouts of one WORK folder's scenes."""
    from calibration.store import load_arena_file
    from explore.rigs.ball import locator_from_calibration, observer_from_calibration

    with np.load(work / "views.npz") as z:
        places, frames = z["places"], z["frames"]
    data = load_arena_file(work / "cal" / RIG_ID / "arena.json")
    observe, locate = observer_from_calibration(data), locator_from_calibration(data)
    from vision.observation import square_observation

    arm_views = np.stack([observe(f, 64) for f in frames])
    raw_views = np.stack([square_observation(f, 64) for f in frames])
    tracked = np.stack([locate(f) for f in frames])
    twin_views = twin_renders(places, 64)
    arm_code, twin_code = model.encode_bgr(arm_views), model.encode_bgr(twin_views)
    return {
        "places": places, "tracked": tracked,
        "gap": np.linalg.norm(arm_code - twin_code, axis=1) / spread,
        "arm": affine(arm_code), "twin": affine(twin_code),
        "arm_nn": neighbours(arm_code), "twin_nn": neighbours(twin_code),
        "raw": affine(model.encode_bgr(raw_views)),
    }  # fmt: skip


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("work", type=Path, nargs="+", help="WORK folders of arm_observation.py")
    ap.add_argument("--model", type=Path, required=True, help="a twin-trained SAE or VAE folder")
    ap.add_argument("--data", type=Path, required=True, help="the twin dataset for the readout")
    ap.add_argument("--figure", type=Path, default=None)
    ap.add_argument("--markers", action="store_true", help="the markers' own code gap too")
    args = ap.parse_args()
    model = load_model(args.model)
    with np.load(args.data) as z:
        images, ball = z["images"], z["ball"]
    codes = model.encode_bgr(images)
    spread = float(np.sqrt(codes.var(axis=0).sum()))
    affine, neighbours = affine_readout(codes, ball), neighbour_readout(codes, ball)
    fit, _ = cell_errors(affine(codes), ball)
    print(f"model {args.model}; readout fitted on {len(ball)} twin outcomes of {args.data}")
    print(f"affine readout on its own fit: {q(fit)} cells (median / 90th percentile)")
    print(
        "| stand-in | scenes | code gap | arm code -> tracker: cells | cell index | 10-NN: cells "
        "| twin code -> place: cells | 10-NN | tracker -> place, mm | centre square's code -> "
        "tracker: cells |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    results = {}
    for work in args.work:
        results[work.name] = r = measure(work, model, affine, neighbours, spread)
    rows = [*results.items(), ("all", {k: np.concatenate([r[k] for r in results.values()])
                                        for k in next(iter(results.values()))})]  # fmt: skip
    for name, r in rows:
        dist, cheb = cell_errors(r["arm"], r["tracked"])
        nn, _ = cell_errors(r["arm_nn"], r["tracked"])
        own, _ = cell_errors(r["twin"], r["places"])
        own_nn, _ = cell_errors(r["twin_nn"], r["places"])
        mm = np.linalg.norm(r["tracked"] - r["places"], axis=1) * 1000
        raw, _ = cell_errors(r["raw"], r["tracked"])
        print(
            f"| {name} | {len(r['places'])} | {q(r['gap'])} | {q(dist)} | {q(cheb)} | {q(nn)} | "
            f"{q(own)} | {q(own_nn)} | {q(mm)} | {q(raw)} |"
        )
    if args.markers:
        with np.load(args.work[0] / "views.npz") as z:
            places = z["places"]
        marked, plain = marked_views(places), twin_renders(places, 64)
        gap = np.linalg.norm(model.encode_bgr(marked) - model.encode_bgr(plain), axis=1) / spread
        print(
            f"code gap of the markers alone (nominal served twin, {len(places)} scenes): {q(gap)}"
        )
    if args.figure is not None:
        figure(args.figure, rows[-1][1])
    return 0


def marked_views(places: np.ndarray) -> np.ndarray:
    """The nominal served twin's 64 px views (the twin's camera, the markers on the floor)."""
    from sim.standin.hidden import nominal_rig
    from sim.standin.lens import ServedFrames
    from sim.standin.served import served_twin
    from vision.observation import square_observation

    twin, plan = served_twin(nominal_rig())
    frames = ServedFrames(twin, plan)
    try:
        out = []
        for xy in places:
            twin.reset((float(xy[0]), float(xy[1])))
            out.append(square_observation(frames(), 64))
        return np.stack(out)
    finally:
        frames.close()
        twin.close()


def figure(path: Path, r: dict[str, np.ndarray]) -> None:
    """Where the readout of the arm's code puts the ball against the tracker, over the arena;
    and the distribution of its error in cells, beside the twin's code's."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax, bx) = plt.subplots(1, 2, figsize=(10, 4.6))
    t, a = r["tracked"], r["arm"]
    for (x0, y0), (x1, y1) in zip(t, a, strict=True):
        ax.plot([x0, x1], [y0, y1], color="0.6", lw=0.7)
    ax.scatter(t[:, 0], t[:, 1], s=14, label="tracker (arm)", color="tab:blue")
    ax.scatter(
        a[:, 0], a[:, 1], s=14, marker="x", label="readout of the arm's code", color="tab:red"
    )
    for radius in (0.13, 0.17):
        ax.add_patch(plt.Circle((0, 0), radius, fill=False, ls=":", color="0.5"))
    ax.set_aspect("equal")
    ax.set_xlim(-0.2, 0.2)
    ax.set_ylim(-0.2, 0.2)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.legend(fontsize=8, loc="upper right")
    ax.set_title("where the twin-trained code puts the arm's ball", fontsize=9)
    for key, truth, label in (("arm", "tracked", "arm's view -> tracker"),
                              ("twin", "places", "twin's render -> place"),
                              ("raw", "tracked", "centre square (before) -> tracker")):  # fmt: skip
        dist, _ = cell_errors(r[key], r[truth])
        dist = np.sort(dist[np.isfinite(dist)])
        bx.plot(dist, np.arange(1, len(dist) + 1) / len(dist), label=label)
    bx.axvline(1, color="0.5", ls=":")
    bx.axvline(2, color="0.5", ls=":")
    bx.set_xlabel("readout error (cells of the 30 x 30 metric)")
    bx.set_ylabel("share of scenes")
    bx.legend(fontsize=8)
    fig.tight_layout()
    save_figure(fig, path)


if __name__ == "__main__":
    raise SystemExit(main())
