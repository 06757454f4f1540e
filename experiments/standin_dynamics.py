"""The servos' fit on stand-in rigs: for each seed and bus, ``ergo twin serve --stand-in SEED``
(real time, over a pty), ``ergo calibrate dynamics`` through it, then the fitted parameters
against the hidden ones: whether each 95 % interval holds the hidden value, how wide it is,
whether the fit calls it identified, the held-out RMS error nominal against fitted, and the
wall time of the recording and of the fit. Prints one block per rig, the coverage table per
bus and parameter, and a JSON summary.

The joint calibration is written from the hidden mounting (directions, offsets), standing in
for ``ergo calibrate joints`` driven by the stand-in's hands, which recovers the offsets within
0.03 deg (docs/standin.md); the dynamics fit itself never reads the hidden file.

    python experiments/standin_dynamics.py [--seeds 0 1 2] [--buses dynamixel canopen] [--out FILE]
        [--keep DIR] [--record-only] [--repeats N] [--refit LABEL [--code CHECKOUT]]
        [--table LABEL ...]

With ``--keep DIR`` each rig's result is also written to ``DIR/result-BUS-SEED.json`` as soon
as it is measured, and a rig whose result is there is not measured again (run the same command
again after a stop to finish the rest). Each result holds the served twin's real-time lines
(``real-time loop: ...``, ``emulated drives: ...``) from the server's log.

``--record-only`` records and checks (``ergo calibrate dynamics --record-only``) and fits
nothing; ``--refit LABEL`` records nothing: it fits the recordings kept in ``DIR`` again
(``ergo calibrate dynamics --recording``, into ``DIR/refit-LABEL``; results
``DIR/result-BUS-SEED-LABEL.json``), with this checkout's code or, with ``--code CHECKOUT``,
another's (a ``git worktree`` of an earlier commit: the fit before a change, on the same
recordings). ``--table LABEL [LABEL ...]`` prints the coverage tables of results already
measured ("" for the recordings' own fits).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


from calibration import store  # noqa: E402
from calibration.dynamics.excitation import REPEATS  # noqa: E402
from calibration.dynamics.recording import Recording  # noqa: E402
from robot.spec import ERGO_JR_JOINTS, ergo_jr_spec  # noqa: E402
from testkit.standin_owner import ServedRig  # noqa: E402
from testkit.standin_truth import read_hidden  # noqa: E402

ERGO = [str(Path(sys.executable).parent / "ergo")]
FIELDS = ("kp", "damping", "armature", "frictionloss")
TOLERANCE = 0.15  # "within 15 %" of the hidden value (a column beside the intervals' coverage)


def joints_from_truth(hidden_path: Path, rig: str, cal_dir: Path) -> None:
    hidden = read_hidden(hidden_path)
    spec = ergo_jr_spec()
    margin = math.radians(5.0)
    store.save(
        "joints",
        rig,
        {
            "names": list(ERGO_JR_JOINTS),
            "offsets": hidden.offsets.tolist(),
            "directions": [int(d) for d in hidden.directions],
            "lower": (spec.lower + margin).tolist(),
            "upper": (spec.upper - margin).tolist(),
            "units": "rad",
        },
        cal_dir,
    )


def truth_floor(rec_path: Path, hidden_path: Path) -> dict:
    """The held-out RMS error of the hidden servos themselves (their delay plus the bus's
    transport, the best of 0-30 ms more), deg: how close any fit can come on this recording."""
    from calibration.dynamics.fit import arm_spec, segment_error
    from calibration.dynamics.recording import Recording

    rec = Recording.load_file(rec_path)
    truth = read_hidden(hidden_path).servos
    spec = arm_spec()
    best = min(
        (
            math.degrees(
                float(
                    np.sqrt(
                        np.mean(segment_error(truth.replace(delay_s=d), rec, "held_out", spec) ** 2)
                    )
                )
            ),
            d,
        )
        for d in truth.delay_s + np.arange(0.0, 0.031, 0.002)
    )
    return {"held_out_rms_deg": best[0], "delay_s": best[1]}


def one(
    bus: str, seed: int, work: Path, record_only: bool = False, repeats: int | None = None
) -> dict:
    hidden_path = work / f"hidden-{bus}-{seed}.json"
    rig = f"s{seed}-{bus}"
    log = hidden_path.with_suffix(".server.log")
    served = ServedRig(bus, seed, hidden_path, flags=["--no-camera"], log=log)
    with served:
        joints_from_truth(hidden_path, rig, work)
        t0 = time.monotonic()
        done = subprocess.run(
            [
                *ERGO,
                "calibrate",
                "dynamics",
                "--rig-id",
                rig,
                "--dir",
                str(work),
                *served.bus_flags(),
                *(["--record-only"] if record_only else []),
                *(["--repeats", str(repeats)] if repeats is not None else []),
            ],
            cwd=ROOT,
            capture_output=True,
            text=True,
            timeout=1800 * (repeats or REPEATS),
        )
        wall = time.monotonic() - t0
    out = {
        "bus": bus, "seed": seed, "repeats": repeats, "rc": done.returncode,
        "wall_s": round(wall, 1),
    }  # fmt: skip
    out["server_lines"] = [
        line.split(": ", 1)[1]
        for line in log.read_text().splitlines()
        if "real-time loop: " in line or "emulated drives: " in line
    ]
    if done.returncode != 0:
        out["error"] = (done.stderr.strip().splitlines() or ["?"])[-1]
        out["server_log_tail"] = log.read_text()[-1500:]
        out["server_rc"] = served.proc.returncode
        return out
    recording = Recording.load_file(work / rig / "dynamics_recording.npz")
    out["record_s"] = recording.meta.get("record_s")
    if record_only:
        return out
    data = store.load("dynamics", rig, work)
    out.update(judge(data, hidden_path))
    out["truth_floor"] = truth_floor(work / rig / "dynamics_recording.npz", hidden_path)
    return out


def judge(data: dict, hidden_path: Path) -> dict:
    """A dynamics.json's ``data`` against the hidden servos: per field and joint the relative
    error, whether the 95 % interval holds the hidden value (``covered``), its width over the
    fitted value, within ``TOLERANCE``, identified (True where the file does not say); the
    held-out RMS errors."""
    truth = read_hidden(hidden_path).servos
    fitted, intervals = data["servos"], data["intervals_95"]
    identifiable = data.get("identifiable", {})
    verdict: dict = {}
    for f in FIELDS:
        t, v = np.asarray(truth.to_dict()[f]), np.asarray(fitted[f])
        lo, hi = np.asarray(intervals[f]).T
        err = v / t - 1.0
        verdict[f] = {
            "hidden": t.tolist(),
            "fitted": v.tolist(),
            "rel_err": err.tolist(),
            "covered": ((lo <= t) & (t <= hi)).tolist(),
            "width": ((hi - lo) / v).tolist(),
            "within": (np.abs(err) <= TOLERANCE).tolist(),
            "identified": list(identifiable.get(f, [True] * len(t))),
            "jackknife_sd": data.get("jackknife_sd", {}).get(f),
        }
    td, vd = truth.delay_s, fitted["delay_s"]
    lo, hi = intervals["delay_s"]
    verdict["delay_s"] = {"hidden": td, "fitted": vd, "interval": [lo, hi]}
    rms = data["held_out_rms_rad"]
    return {
        "params": verdict,
        "held_out_rms_deg": {
            "nominal": math.degrees(rms["nominal"]),
            "fitted": math.degrees(rms["fitted"]),
        },
        "ratio": rms["nominal"] / max(rms["fitted"], 1e-12),
        "record_s": data["recording"]["record_s"],
        "fit_s": data["fit_s"],
        "unidentified": data.get("unidentified", {}),
    }


def refit(bus: str, seed: int, work: Path, label: str, code: Path | None) -> dict:
    """Fit the recording kept in ``work`` again (module docstring, ``--refit``)."""
    rig = f"s{seed}-{bus}"
    recording = work / rig / "dynamics_recording.npz"
    into = work / f"refit-{label}"
    (into / rig).mkdir(parents=True, exist_ok=True)
    env = dict(os.environ)
    if code is not None:
        env["PYTHONPATH"] = str(code.resolve())
    t0 = time.monotonic()
    done = subprocess.run(
        [*ERGO, "calibrate", "dynamics", "--rig-id", rig, "--dir", str(into), "--recording",
         str(recording), "--no-report"],
        cwd=code or ROOT, env=env, capture_output=True, text=True, timeout=3600,
    )  # fmt: skip
    out = {"bus": bus, "seed": seed, "rc": done.returncode, "label": label}
    out["wall_s"] = round(time.monotonic() - t0, 1)
    if done.returncode != 0:
        out["error"] = (done.stderr.strip().splitlines() or ["?"])[-1]
        return out
    out.update(judge(store.load("dynamics", rig, into), work / f"hidden-{bus}-{seed}.json"))
    out["truth_floor"] = truth_floor(recording, work / f"hidden-{bus}-{seed}.json")
    return out


def excess_sd(err: np.ndarray, sd: np.ndarray) -> float:
    """The sd ``m`` of an error shared beyond each value's own sd: ``m >= 0`` with
    ``mean(err^2 / (sd^2 + m^2)) = 1`` (0 when the values' own sds explain the errors), the
    Paule-Mandel estimate of a random effect (J. Res. NBS 87, 377 (1982)) with its mean known
    (0: the mismatch is an error, not a correction). Shapes (K,), log-ratios."""
    from scipy.optimize import brentq

    err, var = np.square(np.asarray(err, float)), np.square(np.asarray(sd, float))

    def excess(m: float) -> float:  # falls as m grows; positive at 0, negative at the top
        return float(np.mean(err / np.maximum(var + m * m, 1e-300))) - 1.0

    if not len(err) or excess(0.0) <= 0.0:
        return 0.0
    return float(brentq(excess, 0.0, float(np.sqrt(np.max(err))) + 1.0, xtol=1e-12))


def mismatch(results: list[dict]) -> str:
    """Per bus and field, over the rigs' joints whose value the fit calls identified: the RMS of
    the log errors (fitted / hidden), and the error beyond what the jackknife's own sd explains
    (``excess_sd``; results whose files hold the jackknife's sd): the measurement of
    ``calibration.dynamics.uncertainty.MISMATCH_SD``, which the intervals add in quadrature to
    the jackknife's (a value the recording does not pin is off by more, and its interval is
    already wide)."""
    lines = [
        "| bus | parameter | RMS log error | beyond the jackknife | joints |",
        "|---|---|---|---|---|",
    ]
    good = [r for r in results if "params" in r]
    for bus in sorted({r["bus"] for r in good}):
        for f in FIELDS:
            p = [r["params"][f] for r in good if r["bus"] == bus]
            pairs = [
                (math.log1p(e), (v.get("jackknife_sd") or [None] * len(v["rel_err"]))[j])
                for v in p
                for j, (e, known) in enumerate(zip(v["rel_err"], v["identified"], strict=True))
                if known
            ]
            err = np.array([e for e, _ in pairs])
            rms = math.sqrt(np.mean(np.square(err)))
            sds = [s for _, s in pairs]
            beyond = "" if None in sds else f"{excess_sd(err, np.array(sds, float)):.4f}"
            lines.append(f"| {bus} | {f} | {rms:.4f} | {beyond} | {len(err)} |")
    return "\n".join(lines)


def table(results: list[dict], title: str) -> str:
    """The coverage table: per bus and field, intervals that hold the hidden value, their
    median width, within 15 %, identified; then the held-out RMS per rig."""
    head = (
        "| bus | parameter | 95 % interval holds the hidden value | median width | "
        "within 15 % | identified (holds / of) |"
    )
    lines = [f"### {title}", "", head, "|---|---|---|---|---|---|"]
    good = [r for r in results if "params" in r]
    for bus in sorted({r["bus"] for r in good}):
        rows = [r for r in good if r["bus"] == bus]
        for f in (*FIELDS, "all"):
            fields = FIELDS if f == "all" else (f,)
            cov = [c for r in rows for g in fields for c in r["params"][g]["covered"]]
            wid = [w for r in rows for g in fields for w in r["params"][g]["width"]]
            win = [c for r in rows for g in fields for c in r["params"][g]["within"]]
            ids = [
                (i, c)
                for r in rows
                for g in fields
                for i, c in zip(
                    r["params"][g]["identified"], r["params"][g]["covered"], strict=True
                )
            ]
            held = sum(c for i, c in ids if i)
            n_id = sum(i for i, _ in ids)
            lines.append(
                f"| {bus} | {f} | {sum(cov)} / {len(cov)} | {100 * np.median(wid):.1f} % | "
                f"{sum(win)} / {len(win)} | {n_id} ({held} / {n_id}) |"
            )
    cov = [c for r in good for g in FIELDS for c in r["params"][g]["covered"]]
    wid = [w for r in good for g in FIELDS for w in r["params"][g]["width"]]
    if cov:
        lines.append(
            f"| all | all | {sum(cov)} / {len(cov)} ({100 * np.mean(cov):.0f} %) | "
            f"{100 * np.median(wid):.1f} % | | |"
        )
    lines += [
        "",
        "| rig | held-out RMS nominal / fitted / hidden servos, deg | delay fitted / hidden, ms |",
        "|---|---|---|",
    ]
    for r in good:
        d = r["params"]["delay_s"]
        lines.append(
            f"| {r['bus']} {r['seed']} | {r['held_out_rms_deg']['nominal']:.3f} / "
            f"{r['held_out_rms_deg']['fitted']:.3f} / {r['truth_floor']['held_out_rms_deg']:.3f} | "
            f"{d['fitted'] * 1e3:.1f} / {d['hidden'] * 1e3:.1f} |"
        )
    return "\n".join(lines)


def show(r: dict) -> None:
    """One rig's block: errors, the intervals' misses (!) and the unidentified (?)."""
    print(
        f"   fit {r['fit_s']} s; held-out RMS nominal {r['held_out_rms_deg']['nominal']:.3f} "
        f"deg, fitted {r['held_out_rms_deg']['fitted']:.3f} deg ({r['ratio']:.1f}x)"
    )
    floor = r["truth_floor"]
    print(
        f"   the hidden servos: held-out RMS {floor['held_out_rms_deg']:.3f} deg (at delay "
        f"{floor['delay_s'] * 1e3:.1f} ms)"
    )
    for f in FIELDS:
        v = r["params"][f]
        errs = " ".join(
            f"{e * 100:+5.0f}%{'' if c else '!'}{'' if i else '?'}[{w * 100:.0f}]"
            for e, c, i, w in zip(
                v["rel_err"], v["covered"], v["identified"], v["width"], strict=True
            )
        )
        print(f"   {f:13s} {errs}")
    d = r["params"]["delay_s"]
    print(
        f"   delay         hidden {d['hidden'] * 1e3:.1f} ms, fitted {d['fitted'] * 1e3:.1f} ms",
        flush=True,
    )


def record_all(args: argparse.Namespace, tmp: Path) -> list[dict]:
    results = []
    for bus in args.buses:
        for seed in args.seeds:
            kept = tmp / f"result-{bus}-{seed}.json"
            if args.keep and kept.exists():
                results.append(json.loads(kept.read_text()))
                print(f"== {bus} seed {seed}: measured before ({kept})", flush=True)
                continue
            r = one(bus, seed, tmp, args.record_only, args.repeats)
            for _ in range(2):  # the link lost on a loaded machine: again, at most twice
                if "error" not in r or "fit failed" in r["error"]:
                    break
                print(f"== {bus} seed {seed}: {r['error'][:160]}... once more", flush=True)
                first = r["error"]
                r = one(bus, seed, tmp, args.record_only, args.repeats)
                r["first_attempt_error"] = first
            results.append(r)
            if args.keep and "error" not in r:
                kept.write_text(json.dumps(r, indent=2))
            print(f"== {bus} seed {seed}: rc {r['rc']}, wall {r['wall_s']} s", flush=True)
            for line in r["server_lines"]:
                print(f"   server: {line}", flush=True)
            if "error" in r:
                print(f"   error: {r['error']}")
                print(f"   server (rc {r['server_rc']}): {r['server_log_tail']}")
                continue
            print(f"   record {r['record_s']} s")
            if not args.record_only:
                show(r)
    return results


def refit_all(args: argparse.Namespace, tmp: Path) -> list[dict]:
    results = []
    for bus in args.buses:
        for seed in args.seeds:
            kept = tmp / f"result-{bus}-{seed}-{args.refit}.json"
            if kept.exists():
                results.append(json.loads(kept.read_text()))
                print(f"== {bus} seed {seed} ({args.refit}): fitted before ({kept})", flush=True)
                continue
            if not (tmp / f"s{seed}-{bus}" / "dynamics_recording.npz").exists():
                print(f"== {bus} seed {seed}: no recording kept in {tmp}", flush=True)
                continue
            r = refit(bus, seed, tmp, args.refit, args.code)
            results.append(r)
            print(f"== {bus} seed {seed} ({args.refit}): rc {r['rc']}, wall {r['wall_s']} s")
            if "error" in r:
                print(f"   error: {r['error']}")
                continue
            kept.write_text(json.dumps(r, indent=2))
            show(r)
    return results


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    p.add_argument("--buses", nargs="+", default=["dynamixel", "canopen"])
    p.add_argument("--out", type=Path, default=None, help="also write the JSON summary here")
    p.add_argument("--keep", type=Path, default=None, help="keep recordings and reports here")
    p.add_argument("--refit", default=None, metavar="LABEL", help="fit the kept recordings again")
    p.add_argument("--code", type=Path, default=None, help="with --refit: this checkout's code")
    p.add_argument("--table", nargs="+", default=None, metavar="LABEL", help="print tables")
    p.add_argument(
        "--record-only", action="store_true", help="record and keep, fit later with --refit"
    )
    p.add_argument(
        "--repeats", type=int, default=None, help="ergo calibrate dynamics --repeats (excitation)"
    )
    p.add_argument(
        "--mismatch", action="store_true",
        help="with --table: also the RMS log errors per bus and parameter (MISMATCH_SD)",
    )  # fmt: skip
    args = p.parse_args()
    if (args.refit is not None or args.table is not None) and args.keep is None:
        p.error("--refit and --table need --keep DIR")
    if args.table is not None:
        for label in args.table:
            suffix = f"-{label}" if label else ""
            found = [
                json.loads(path.read_text())
                for bus in args.buses
                for seed in args.seeds
                if (path := args.keep / f"result-{bus}-{seed}{suffix}.json").exists()
            ]
            print(table(found, label or "the recordings' own fits"))
            print()
            if args.mismatch:
                print(mismatch(found))
                print()
        return 0
    with tempfile.TemporaryDirectory(prefix="standin-dynamics-") as scratch:
        tmp = Path(args.keep or scratch)
        tmp.mkdir(parents=True, exist_ok=True)
        results = refit_all(args, tmp) if args.refit is not None else record_all(args, tmp)
        if not args.record_only:
            print(table(results, args.refit or "the recordings' own fits"))
    if args.out:
        args.out.write_text(json.dumps(results, indent=2))
    print(json.dumps([{k: v for k, v in r.items() if k != "params"} for r in results]))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
