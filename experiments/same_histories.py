"""Whether two campaign folders hold the same histories: every run (strategy, seed) found in
both, record by record (``EpisodeRecord.equals``: parameters, goal, module, kind, outcomes,
images), and its exploration ratio at the published checkpoints.

Used to check that a change leaves a strategy's runs as they were (docs/results_armballs.md,
"Stalls: cause and fix": RPE and RGE-EFR before and after).

    .venv/bin/python experiments/same_histories.py CAMPAIGN_A CAMPAIGN_B

Prints one line per run and exits 1 if any differs (0 if all are equal).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from explore.runs.layout import METRICS_FILE
from plumbing.cli_errors import error


def same_run(a: Path, b: Path) -> tuple[bool, str]:
    """(equal, what was compared or where they part) for two run folders."""
    from explore.runs.metrics import checkpoints, exploration_ratio, read_metrics
    from explore.runs.store import iter_history

    records_a, records_b = list(iter_history(a)), list(iter_history(b))
    for ra, rb in zip(records_a, records_b, strict=False):
        if not ra.equals(rb):
            return False, f"records part at episode {ra.episode}"
    n = len(records_a)
    if n != len(records_b):
        return False, f"{n} against {len(records_b)} records"
    ca, cb = (read_metrics(p / METRICS_FILE)["ball_cells"] for p in (a, b))
    ra, rb = (exploration_ratio(c, checkpoints()) for c in (ca, cb))
    if not np.array_equal(ra, rb, equal_nan=True):
        return False, "exploration ratios differ"
    return True, f"{n} records equal, ratio at 9666 {ra[-1]:.3f}"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("a", type=Path)
    ap.add_argument("b", type=Path)
    args = ap.parse_args(argv)
    runs = sorted(p.relative_to(args.a) for p in args.a.glob("*/seed-*") if p.is_dir())
    common = [r for r in runs if (args.b / r).is_dir()]
    if not common:
        return error(
            f"{args.a} and {args.b} share no STRATEGY/seed-N run folder: give two "
            "campaign folders of `ergo experiment`"
        )
    all_equal = True
    for r in common:
        equal, what = same_run(args.a / r, args.b / r)
        all_equal &= equal
        print(f"{r}: {'equal' if equal else 'DIFFERENT'} ({what})")
    return 0 if all_equal else 1


if __name__ == "__main__":
    sys.exit(main())
