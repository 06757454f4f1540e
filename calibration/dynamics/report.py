"""The fit's report: ``held_out.png`` (per joint, the held-out trajectory of the arm, the
nominal twin and the fitted twin, degrees against seconds) and ``report.html`` (that figure,
the fitted parameters with their 95 % intervals beside the nominal ones, the RMS errors)."""

from __future__ import annotations

import html
import math
from pathlib import Path

import numpy as np

from calibration.dynamics.excitation import HELD_OUT_NAME
from calibration.dynamics.fit import FITTED, FitResult, simulate
from calibration.dynamics.recording import Recording
from sim.servo_model import NOMINAL

UNITS = {"kp": "N.m/rad", "damping": "N.m.s/rad", "armature": "kg.m^2", "frictionloss": "N.m"}


def write_report(rec: Recording, result: FitResult, folder: str | Path) -> tuple[Path, Path]:
    """Write the figure and the page into ``folder``; returns (png, html) paths."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    ct, cmd, mt, meas = rec.segment(HELD_OUT_NAME)
    nominal = simulate(NOMINAL, ct, cmd, mt, meas[0])
    fitted = simulate(result.servos, ct, cmd, mt, meas[0])
    t = mt - ct[0]
    fig, axes = plt.subplots(3, 2, figsize=(11, 8), sharex=True)
    for j, ax in enumerate(axes.T.reshape(-1)):
        name = rec.joint_names[j]
        ax.plot(ct - ct[0], np.degrees(cmd[:, j]), color="0.75", lw=1, label="command")
        ax.plot(t, np.degrees(meas[:, j]), color="k", lw=1.6, label="arm")
        ax.plot(t, np.degrees(nominal[:, j]), color="tab:red", lw=1, ls="--", label="nominal twin")
        ax.plot(t, np.degrees(fitted[:, j]), color="tab:blue", lw=1, label="fitted twin")
        rn = math.degrees(result.held_out_rms_per_joint["nominal"][j])
        rf = math.degrees(result.held_out_rms_per_joint["fitted"][j])
        ax.set_title(f"{name}: RMS nominal {rn:.2f} deg, fitted {rf:.3f} deg", fontsize=9)
        ax.set_ylabel("deg")
    for ax in axes[-1]:
        ax.set_xlabel("s")
    axes[0, 0].legend(fontsize=8, loc="best")
    fig.suptitle(
        f"held-out trajectory ({rec.meta.get('backend', '?')}, rig {rec.meta.get('rig_id', '?')})"
    )
    fig.tight_layout()
    png = folder / "held_out.png"
    fig.savefig(png, dpi=90)
    plt.close(fig)
    page = folder / "report.html"
    page.write_text(_html(rec, result, png.name))
    return png, page


def _html(rec: Recording, result: FitResult, png: str) -> str:
    rows = []
    for f in FITTED:
        for j, name in enumerate(rec.joint_names):
            lo, hi = result.intervals[f][j]
            why = result.identified[f][j]
            rows.append(
                f"<tr><td>{name}</td><td>{f} ({UNITS[f]})</td><td>{NOMINAL.array(f)[j]:.4g}</td>"
                f"<td>{result.servos.array(f)[j]:.4g}</td><td>{lo:.4g} .. {hi:.4g}</td>"
                f"<td class=l>{'yes' if not why else 'no: ' + html.escape(why)}</td></tr>"
            )
    lo, hi = result.intervals["delay_s"]
    rows.append(
        f"<tr><td>all</td><td>delay (ms)</td><td>0</td><td>{result.servos.delay_s * 1e3:.2f}</td>"
        f"<td>{lo * 1e3:.2f} .. {hi * 1e3:.2f}</td><td class=l>the whole command path</td></tr>"
    )
    notes = "".join(f"<li>{html.escape(n)}</li>" for n in result.notes) or "<li>none</li>"
    ratio = result.held_out_rms_nominal / max(result.held_out_rms_fitted, 1e-12)
    rig = html.escape(str(rec.meta.get("rig_id")))
    backend = html.escape(str(rec.meta.get("backend")))
    created = html.escape(str(rec.meta.get("created")))
    style = (
        "body{font-family:sans-serif;max-width:70em}td,th{padding:2px 8px;text-align:right}"
        "td.l{text-align:left}"
    )
    return f"""<!doctype html>
<html><head><meta charset="utf-8"><title>servo fit: {rig}</title>
<style>{style}</style>
</head><body>
<h1>The twin's servos fitted to rig {rig}</h1>
<p>Backend {backend}, recorded {created};
fit with mujoco.sysid in {result.fit_s:.1f} s. Held-out RMS error: nominal twin
{math.degrees(result.held_out_rms_nominal):.3f} deg, fitted twin
{math.degrees(result.held_out_rms_fitted):.3f} deg ({ratio:.1f}x lower); training RMS
{math.degrees(result.train_rms_fitted):.3f} deg.</p>
<img src="{png}" alt="held-out trajectories" width="100%">
<h2>Parameters (95 % intervals: a block jackknife and the model's mismatch, docs/dynamics.md)</h2>
<p>"identified: no": the recording does not pin that parameter (its interval is wide); its
fitted value reproduces the arm as well as others would, and is no measurement of the servo.</p>
<table><tr><th>joint</th><th>parameter</th><th>nominal</th><th>fitted</th><th>95 % interval</th>
<th>identified</th></tr>
{"".join(rows)}
</table>
<h2>Notes</h2><ul>{notes}</ul>
</body></html>
"""
