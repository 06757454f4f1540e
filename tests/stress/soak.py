"""Soak: N episodes with ~1% faults; a failed episode is retried by resuming the run
(testkit/fault_soak.py says what is injected and reported).

    python tests/stress/soak.py                        # 2000 episodes over the emulated serial bus
    python tests/stress/soak.py --episodes 300 --fault-rate 0.01 --bus serial
    python tests/stress/soak.py --bus arm              # twin rig, faults injected at the Arm level
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

from sim.headless import ensure_headless_gl

ensure_headless_gl()  # before MuJoCo is imported

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # testkit/, not installed
from testkit.fault_soak import soak  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description="soak with injected faults")
    ap.add_argument("--episodes", type=int, default=2000)
    ap.add_argument("--fault-rate", type=float, default=0.01)
    ap.add_argument("--bus", choices=("serial", "arm"), default="serial")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, help="run folder (default: a temporary one)")
    args = ap.parse_args()
    out = Path(tempfile.mkdtemp(prefix="soak-")) / "run" if args.out is None else args.out
    result = soak(args.episodes, args.fault_rate, args.bus, args.seed, out)
    print(json.dumps(result, indent=2))
    return 0 if result["lost_episodes"] == 0 and result["history_ok"] else 1


if __name__ == "__main__":
    sys.exit(main())
