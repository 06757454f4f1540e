"""Why does goal exploration reach fewer or more ball cells than RPE? The inverse model of
finished runs, engineered (rge-efr, mge-efr) or learned (the VAEs', the spatial autoencoder's):
what each goal episode's nearest neighbour was and did (testkit/inverse_model.py says
what is measured).

    .venv/bin/python experiments/diagnose_inverse_model.py RUN [RUN ...] [--vae DIR] [--figure PNG]

``--figure``: per run, the arena distance of pairs of its outcomes against their distance in
its goal space, and the distribution of the context mismatch over its goal episodes.
``--vae`` overrides the VAE folder recorded in a latent run's config.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # testkit/, not installed
from testkit.inverse_model import DiagnosisError, diagnose, figure


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", type=Path, nargs="+")
    ap.add_argument(
        "--vae", type=Path, help="model folder (VAE, or SAE for *-sae runs) of latent runs "
        "(default: the run's)",
    )  # fmt: skip
    ap.add_argument("--figure", type=Path, help="write the two-panel figure (PNG) here")
    args = ap.parse_args()
    results: dict[str, dict[str, np.ndarray]] = {}
    for run in args.runs:
        arrays: dict[str, np.ndarray] = {}
        try:
            d = diagnose(run, args.vae, arrays)
        except DiagnosisError as exc:
            print(f"diagnose_inverse_model: {exc}", file=sys.stderr)
            return 2
        results[f"{run.parent.parent.name}/{run.parent.name}/{run.name}"] = arrays
        print(
            f"{run}: {d['goal_episodes']:.0f} goal episodes; the neighbour had moved the ball in "
            f"{d['neighbour_moved']:.1%}; the ball moved in {d['moved']:.1%} (after a moving "
            f"neighbour {d['moved_after_moving_neighbour']:.1%}, after a still one "
            f"{d['moved_after_still_neighbour']:.1%}); a new cell in {d['new_cell']:.1%}; "
            f"the ball started {d['start_gap_m'] * 1000:.0f} mm and ended "
            f"{d['ball_gap_m'] * 1000:.0f} mm from the neighbour's (medians); "
            f"|theta - neighbour's| {d['theta_gap']:.2f}; moved in "
            f"{d['moved_all_episodes']:.1%} of all episodes"
        )
    if args.figure:
        figure(results, args.figure)
        print(f"figure: {args.figure}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
