"""``ergo twin serve --rig-id X``: the served twin's servos are rig X's fitted ``dynamics.json``
(``ergo calibrate dynamics``), said in one line; without the file the nominal servos, said in
one line; a damaged file, or ``--rig-id`` with ``--stand-in``, is one line and no server."""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from calibration import store
from sim.servo_model import NOMINAL
from sim.standin.hidden import StandinError
from sim.standin.served import open_served_rig
from testkit.standin_owner import ServedRig

ROOT = Path(__file__).resolve().parents[3]
ERGO_SERVE = [sys.executable, "-m", "explore.cli", "twin", "serve"]
START_BOUND_S = 60.0  # against hangs (the server imports MuJoCo), not a target
# A weak, slow arm's fitted servos (as stand-in 34's: kp about 0.57x nominal), with a delay.
FITTED = NOMINAL.replace(
    kp=[2.0, 1.9, 2.1, 2.0, 1.95, 2.05],
    damping=[0.06] * 6,
    armature=[0.0004] * 6,
    frictionloss=[0.002] * 6,
    delay_s=0.014,
)
# The arm leaning forward (m2) with the forearm out (m3): gravity loads m2 and m3.
POSE = np.array([0.0, 0.6, -0.3, 0.0, 0.0, 0.0])


def save_fitted(root: Path, rig_id: str) -> Path:
    payload = {
        "servos": FITTED.to_dict(),
        "recording": {"path": "r.npz", "sha256": "0" * 64},
        "held_out_rms_rad": {"nominal": 0.02, "fitted": 0.004},
    }
    return store.save("dynamics", rig_id, payload, root)


def served(rig_id: str | None) -> object:
    return open_served_rig(argparse.Namespace(rig_id=rig_id, stand_in=None, hidden=None))


def sag(twin) -> np.ndarray:
    """How far each joint sits from its target after 1.5 s held at ``POSE``, rad (6,)."""
    twin.data.qpos[twin._qpos_idx] = POSE
    twin.set_torque(True)
    twin.set_targets(POSE)
    twin.step(1.5)
    return np.abs(twin.joint_positions() - POSE)


def test_the_served_twin_has_the_rigs_fitted_servos(tmp_path, monkeypatch):
    monkeypatch.setenv(store.ENV_DIR, str(tmp_path))
    path = save_fitted(tmp_path, "arm9")
    rig = served("arm9")
    # read back from the compiled model (and the twin's delay queue), not the file
    assert rig.twin.servos == FITTED
    assert rig.twin.servos.kp != NOMINAL.kp
    assert rig.lines == [
        f"servos of rig arm9: fitted, from {path} (delay 14.0 ms, kp 1.90-2.10 N.m/rad)"
    ]
    # and it moves as weaker servos do: held against gravity, m2 sags more (kp ~0.57x)
    nominal = served("nofile")
    fitted_sag, nominal_sag = sag(rig.twin), sag(nominal.twin)
    assert nominal_sag[1] > 1e-3, nominal_sag  # gravity does load m2 at this pose
    assert fitted_sag[1] > 1.4 * nominal_sag[1], (fitted_sag, nominal_sag)


def test_without_the_file_the_servos_are_nominal_and_it_says_so(tmp_path, monkeypatch):
    monkeypatch.setenv(store.ENV_DIR, str(tmp_path))
    rig = served("nofile")
    assert rig.twin.servos == NOMINAL
    expected = tmp_path / "nofile" / "dynamics.json"
    assert rig.lines == [f"servos of rig nofile: nominal (no dynamics calibration {expected})"]
    assert served(None).lines == []  # no --rig-id: the nominal twin, as before


def test_a_damaged_file_a_bad_id_and_a_stand_in_are_one_line(tmp_path, monkeypatch):
    monkeypatch.setenv(store.ENV_DIR, str(tmp_path))
    path = save_fitted(tmp_path, "arm9")
    path.write_text("{")
    with pytest.raises(StandinError, match=r"dynamics.json: not valid JSON .* not ignored\)$"):
        served("arm9")
    with pytest.raises(StandinError, match=r"^--rig-id: rig id 'a/b' must be"):
        served("a/b")
    with pytest.raises(StandinError, match="--rig-id and --stand-in"):
        open_served_rig(argparse.Namespace(rig_id="arm9", stand_in=3, hidden=None))


@pytest.mark.slow
def test_ergo_twin_serve_rig_id_end_to_end(tmp_path):
    env = {**os.environ, store.ENV_DIR: str(tmp_path)}
    path = save_fitted(tmp_path, "arm9")
    rig = ServedRig("dynamixel", None, flags=["--rig-id", "arm9", "--no-camera"], env=env)
    with rig:
        assert rig.lines["servos"].startswith(f"servos of rig arm9: fitted, from {path} (")
        assert rig.camera_url is None
    assert rig.proc.returncode == 0
    path.write_text('{"schema": "ergo-explore/calibration"}')
    done = subprocess.run(
        [*ERGO_SERVE, "--bus", "dynamixel", "--rig-id", "arm9", "--no-camera"],
        cwd=ROOT, env=env, capture_output=True, text=True, timeout=START_BOUND_S,
    )  # fmt: skip
    assert done.returncode == 2
    assert done.stderr.strip() == (
        f"ergo: error: {path}: field 'kind' is missing (a damaged twin calibration is not ignored)"
    )
    assert done.stdout == ""
