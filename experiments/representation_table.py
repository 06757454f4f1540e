"""The representation table of docs/results_seeds100.md: per training seed of each model of a paper
campaign folder (``make paper``), how well it locates the ball (a diagnostic only: held-out
linear R^2 of the ball's, and the distractor's, position from the code), its KL per latent (the
VAEs), the selection criterion (held-out explained pixel variance, which never sees a label),
which seed the criterion chose, and the ball cells the model's exploration reached (rge-<kind>,
seed 100, 1500 episodes, where it was run).

    .venv/bin/python experiments/representation_table.py runs/paper
"""

from __future__ import annotations

import argparse
import csv
import json
from pathlib import Path

import numpy as np
from script_helpers import linear_r2  # experiments/script_helpers.py, beside this script

from explore.runs.layout import METRICS_FILE
from vision.representation_quality import heldout_split

# model folder -> (dataset, kind)
MODELS = {
    "sae": ("outcomes.npz", "sae"),
    "vae": ("outcomes.npz", "vae"),
    "betavae": ("outcomes.npz", "vae"),
    "sae_distractor": ("outcomes_distractor.npz", "sae"),
    "betavae_distractor": ("outcomes_distractor.npz", "vae"),
}
HELDOUT = 0.1  # as ergo sae/vae train hold out


def held_out_r2(code: np.ndarray, target: np.ndarray, train: np.ndarray, test: np.ndarray) -> float:
    """Held-out R^2 (mean over the target's columns) of an affine fit code (n, d) -> target
    (n, k) on the rows ``train``, scored on the rows ``test``."""
    return linear_r2(code[train], target[train], code[test], target[test], pooled=False)


def final_cells(run: Path) -> int | None:
    metrics = run / METRICS_FILE
    if not metrics.exists():
        return None
    with open(metrics) as f:
        rows = list(csv.DictReader(f))
    return int(rows[-1]["ball_cells"]) if rows else None


def rows_for(out: Path, name: str) -> list[str]:
    data_file, kind = MODELS[name]
    folder = out / "models" / name
    selection = folder / "selection.json"
    if not selection.exists():
        return []
    chosen = json.loads(selection.read_text())["chosen"]
    with np.load(out / "data" / data_file, allow_pickle=False) as z:
        images, ball = z["images"], z["ball"]
        distractor = z["distractor"] if "distractor" in z.files else None
    rows = []
    for seed_dir in sorted(folder.glob("seed-*"), key=lambda p: int(p.name[5:])):
        seed = int(seed_dir.name[5:])
        train, test = heldout_split(len(images), HELDOUT, seed)
        if kind == "sae":
            from vision.spatial_ae import load_sae

            model = load_sae(seed_dir)
            kl = "-"
        else:
            from vision.vae import load_vae

            model = load_vae(seed_dir)
            kl = " ".join(
                f"{v:.1f}" for v in sorted(model.config.kl_per_latent or [], reverse=True)
            )
        code = model.encode_bgr(images)
        r2 = f"{held_out_r2(code, ball, train, test):.3f}"
        if distractor is not None:
            r2 += f" / {held_out_r2(code, distractor, train, test):.3f}"
        crit = model.config.heldout_explained_variance
        # the exploration of this model (the campaign script's per_model/NAME-SEED/rge-NAME)
        cells = final_cells(out / "per_model" / f"{name}-{seed}" / f"rge-{name}" / "seed-100")
        rows.append(
            f"| {name} | {seed}{' (chosen)' if seed == chosen else ''} | {r2} | {kl} | "
            f"{crit:.3f} | {'-' if cells is None else cells} |"
        )
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path)
    args = ap.parse_args()
    lines = [
        "| model | training seed | held-out R^2 ball (/ distractor) | KL per latent, nats, "
        "largest first | held-out explained pixel variance | ball cells, rge, seed 100, "
        "1500 episodes |",
        "|---|---|---|---|---|---|",
    ]
    for name in MODELS:
        lines += rows_for(args.out, name)
    text = "\n".join(lines)
    (args.out / "representation_table.md").write_text(text + "\n")
    print(text)


if __name__ == "__main__":
    main()
