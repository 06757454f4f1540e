"""The fit against stand-ins' hidden servos (read here, never by the fit): a small recording
made over a served stand-in, fitted again (its 95 % intervals hold the hidden servo); and,
slow, end to end: ``ergo twin serve --bus dynamixel --stand-in 2`` in real time, ``ergo
calibrate dynamics --port PTY --joints m3`` through it, the fitted m3 against the hidden servo,
the held-out check."""

from __future__ import annotations

import math
import os
import subprocess
import sys
import threading
import time
from pathlib import Path
from queue import Empty, Queue

import numpy as np
import pytest

from calibration import store
from robot.spec import ERGO_JR_JOINTS, ergo_jr_spec
from testkit.standin_truth import read_hidden

ROOT = Path(__file__).resolve().parents[3]
ERGO = [sys.executable, "-m", "explore.cli"]
SEED = (
    2  # measured in experiments/standin_dynamics.py: m3's kp -9 %, damping -4 % over all six joints
)
# A recording over the Dynamixel pty of stand-in 301 (a development seed): ``python
# experiments/standin_dynamics.py --seeds 301 --buses dynamixel --keep DIR``, cut to m3's
# segment and the held-out one (26 kB). It was made before recordings kept their
# ``position_resolution``: the XL-320's 300 deg / 1023 was added to its meta.
FIXTURE = Path(__file__).parent / "data" / "standin-301-dynamixel-m3.npz"
FIXTURE_SEED = 301
FIELDS = ("kp", "damping", "armature", "frictionloss")


def test_the_intervals_hold_a_stand_ins_hidden_servo():
    """m3 fitted from a served stand-in's recording (the other joints nominal, as with
    ``--joints m3``): each of its 95 % intervals holds the hidden value, the damping is
    identified within 15 %, a parameter said not identified has a wide interval and a reason.
    The textbook intervals the fit gave before excluded the hidden damping (+1.5 % against
    +-1.2 %) and armature (+83 % against +-5 %) of this recording."""
    from calibration.dynamics.fit import fit
    from calibration.dynamics.recording import Recording
    from sim.standin.hidden import draw_hidden

    result = fit(Recording.load_file(FIXTURE))
    truth = draw_hidden(FIXTURE_SEED).servos
    k = 2  # m3
    for field in FIELDS:
        lo, hi = result.intervals[field][k]
        assert lo <= truth.array(field)[k] <= hi, (field, lo, truth.array(field)[k], hi)
        why = result.identified[field][k]
        if why:
            assert "does not pin it" in why and hi / lo > 2.0, (field, why, lo, hi)
    assert not result.identified["damping"][k]
    assert abs(result.servos.array("damping")[k] / truth.array("damping")[k] - 1) < 0.15
    assert result.held_out_rms_fitted < result.held_out_rms_nominal


@pytest.mark.slow
def test_the_fit_over_a_served_standin_finds_its_hidden_servo(tmp_path):
    hidden = tmp_path / "hidden.json"
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    with open(tmp_path / "server.log", "w") as log:
        proc = subprocess.Popen(
            [*ERGO, "twin", "serve", "--bus", "dynamixel", "--stand-in", str(SEED),
             "--hidden", str(hidden), "--no-camera"],
            cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=log, text=True,
        )  # fmt: skip
        try:
            lines: Queue[str] = Queue()
            threading.Thread(
                target=lambda: [lines.put(x) for x in proc.stdout], daemon=True
            ).start()
            port, deadline = None, time.monotonic() + 120
            while time.monotonic() < deadline:
                try:
                    line = lines.get(timeout=1.0)
                except Empty:
                    continue
                if " bus " in line:
                    port = line.strip().rsplit(" ", 1)[1]
                if line.startswith("stand-in"):
                    break
            assert port is not None, (tmp_path / "server.log").read_text()[-2000:]
            truth = read_hidden(hidden)
            # the joint calibration from the hidden mounting, as `ergo calibrate joints` finds
            # it (within 0.03 deg, docs/standin.md)
            spec = ergo_jr_spec()
            store.save("joints", "s", {
                "names": list(ERGO_JR_JOINTS), "offsets": truth.offsets.tolist(),
                "directions": [int(d) for d in truth.directions],
                "lower": (spec.lower + 0.1).tolist(), "upper": (spec.upper - 0.1).tolist(),
            }, tmp_path)  # fmt: skip
            done = subprocess.run(
                [*ERGO, "calibrate", "dynamics", "--rig-id", "s", "--dir", str(tmp_path),
                 "--port", port, "--joints", "m3", "--repeats", "1", "--no-report"],
                cwd=ROOT, env=env, capture_output=True, text=True, timeout=900,
            )  # fmt: skip
        finally:
            proc.terminate()
            proc.wait(timeout=20)
    assert done.returncode == 0, done.stderr[-2000:]
    data = store.load("dynamics", "s", tmp_path)
    fitted = data["servos"]
    for field in ("kp", "damping"):
        err = fitted[field][2] / truth.servos.to_dict()[field][2] - 1
        assert abs(err) < 0.15, (field, err)
    rms = data["held_out_rms_rad"]
    assert rms["fitted"] < rms["nominal"], rms
    # the delay is the whole command path seen from the host: the servo's plus the bus's
    assert truth.servos.delay_s <= fitted["delay_s"] <= truth.servos.delay_s + 0.03
    assert math.isfinite(data["fit_s"]) and np.all(np.isfinite(fitted["frictionloss"]))
