"""``ergo calibrate dynamics`` end to end on the twin (in process): a recording of one joint,
the fit, ``dynamics.json`` and the report, ``calibrate show``; bad input keeps the previous
calibration; the twin rig builds its servos from the file and run.json records it."""

from __future__ import annotations

import copy
import json
import math

import numpy as np
import pytest

from calibration import store
from explore.cli import main

from .conftest import TRUTH


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory):
    root = tmp_path_factory.mktemp("cal")
    # one repeat (the default's three cost the suite a longer fit; test_fit.py checks them)
    rc = main(["calibrate", "dynamics", "--rig-id", "tw", "--dir", str(root), "--joints", "m3",
               "--repeats", "1"])  # fmt: skip
    assert rc == 0
    return root


def test_the_command_records_fits_and_saves(calibrated, capsys):
    folder = calibrated / "tw"
    data = store.load("dynamics", "tw", calibrated)
    # the twin in process is the nominal twin: the fit finds it
    np.testing.assert_allclose(data["servos"]["kp"], 3.5, rtol=0.02)
    assert data["recording"]["sha256"] == store.file_sha256(folder / "dynamics_recording.npz")
    assert (folder / "dynamics_report" / "held_out.png").stat().st_size > 10_000
    page = (folder / "dynamics_report" / "report.html").read_text()
    assert "Held-out RMS error" in page and "<th>identified</th>" in page
    # the twin's exact readings pin m3's servo; the joints not recorded keep the nominal one
    # and say so, in the file as in the report
    assert [data["identifiable"][f][2] for f in ("kp", "damping")] == [True, True]
    assert data["identifiable"]["kp"][0] is False
    assert data["unidentified"]["m1.kp"].startswith("not recorded")
    assert not any(k.startswith("m3.") for k in data["unidentified"])
    lo, hi = np.asarray(data["intervals_95"]["kp"])[2]
    assert lo <= data["servos"]["kp"][2] <= hi
    # what the recording alone says (the jackknife's sd of the log-ratio): plain JSON numbers,
    # None for a joint not recorded; on the twin in process (no mismatch) the interval is t sd
    sd = data["jackknife_sd"]["kp"]
    assert sd[0] is None and 0.0 < sd[2] < math.log(hi / data["servos"]["kp"][2])
    assert main(["calibrate", "show", "--rig-id", "tw", "--dir", str(calibrated)]) == 0
    line = capsys.readouterr().out.strip().splitlines()[-1]
    assert line.startswith("dynamics: delay ") and "m3 kp 3.5" in line and "sha256 " in line


def _rec_with(calibrated, tmp_path, change):
    from calibration.dynamics.recording import Recording

    rec = Recording.load_file(calibrated / "tw" / "dynamics_recording.npz")
    rec = copy.deepcopy(rec)
    change(rec)
    return rec.save(tmp_path / "bad.npz")


@pytest.mark.parametrize(
    "change, words",
    [
        (lambda r: r.meta.update(complete=False), "recording refused: the recording was cut short"),
        (
            lambda r: r.measured.__setitem__(slice(None), r.measured[0]),
            "recording refused: m3 did not move",
        ),
    ],
)
def test_bad_recordings_are_one_line_and_keep_the_calibration(
    calibrated, tmp_path, capsys, change, words
):
    path = store.calibration_path("dynamics", "tw", calibrated)
    before = path.read_bytes()
    bad = _rec_with(calibrated, tmp_path, change)
    args = ["calibrate", "dynamics", "--rig-id", "tw", "--dir", str(calibrated)]
    assert main([*args, "--recording", str(bad)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"ergo: error: {words}"), err
    assert err[0].endswith(f"{path} unchanged")
    assert path.read_bytes() == before


def test_a_damaged_recording_file_is_one_line(tmp_path, capsys):
    bad = tmp_path / "x.npz"
    bad.write_bytes(b"not a zip")
    assert main(["calibrate", "dynamics", "--rig-id", "q", "--dir", str(tmp_path),
                 "--recording", str(bad)]) == 2  # fmt: skip
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "not a readable dynamics recording" in err[0]


def test_an_unknown_joint_is_one_line(tmp_path, capsys):
    assert main(["calibrate", "dynamics", "--rig-id", "q", "--dir", str(tmp_path),
                 "--joints", "m9"]) == 2  # fmt: skip
    assert "--joints: unknown joint(s) m9" in capsys.readouterr().err


def test_no_repeats_is_one_line(tmp_path, capsys):
    assert main(["calibrate", "dynamics", "--rig-id", "q", "--dir", str(tmp_path),
                 "--repeats", "0"]) == 2  # fmt: skip
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["ergo: error: --repeats must be 1 or more, got 0"], err
    assert not (tmp_path / "q").exists()


def test_a_damaged_dynamics_file_is_refused_by_show(tmp_path, capsys):
    path = store.calibration_path("dynamics", "d", tmp_path)
    path.parent.mkdir(parents=True)
    doc = {"schema": store.SCHEMA, "kind": "dynamics", "version": 1, "rig_id": "d",
           "created": "2026-12-02T00:00:00+00:00", "data": {"servos": {"kp": [1]}}}  # fmt: skip
    path.write_text(json.dumps(doc))
    assert main(["calibrate", "show", "--rig-id", "d", "--dir", str(tmp_path)]) == 1
    out = capsys.readouterr().out
    assert "dynamics: INVALID:" in out and "field 'servos' is not a servo model" in out


def test_the_twin_rig_builds_its_servos_from_the_fit_and_run_json_records_it(tmp_path, monkeypatch):
    from explore.rigs.rig import RigConfig, RigError, make_rig
    from explore.runs.config import RunConfig
    from explore.runs.inputs import current_inputs

    monkeypatch.setenv(store.ENV_DIR, str(tmp_path))
    payload = {
        "servos": TRUTH.to_dict(),
        "recording": {"path": "r.npz", "sha256": "0" * 64},
        "held_out_rms_rad": {"nominal": 0.02, "fitted": 0.001},
    }
    path = store.save("dynamics", "arm7", payload)
    rig = make_rig(RigConfig("sim", "arm7"))
    assert rig.sensor.twin.servos == TRUTH
    assert make_rig(RigConfig("sim")).sensor.twin.servos.kp == (3.5,) * 6  # no file: nominal
    config = RunConfig.from_dict(
        {**RunConfig().to_dict(), "rig": {"name": "sim", "rig_id": "arm7", "options": {}}}
    )
    inputs = current_inputs(config)
    assert inputs == [
        {"kind": "dynamics", "path": str(path.resolve()), "sha256": store.file_sha256(path)}
    ]
    path.write_text("{")
    with pytest.raises(RigError, match=r"dynamics.json: not valid JSON .* not ignored"):
        make_rig(RigConfig("sim", "arm7"))


def test_the_gymnasium_env_takes_the_rig_id(tmp_path, monkeypatch):
    gym = pytest.importorskip("gymnasium")
    import explore.export.gym_env  # noqa: F401 - registers the environments

    monkeypatch.setenv(store.ENV_DIR, str(tmp_path))
    store.save(
        "dynamics", "arm8",
        {"servos": TRUTH.to_dict(), "recording": {"path": "r.npz", "sha256": "0" * 64},
         "held_out_rms_rad": {"nominal": 0.02, "fitted": 0.001}},
    )  # fmt: skip
    env = gym.make("ergo_explore/ArmBall-v0", rig_id="arm8")
    try:
        assert env.unwrapped.rig.sensor.twin.servos == TRUTH
    finally:
        env.close()


def test_a_bus_recording_gets_the_models_mismatch_in_its_intervals(calibrated, tmp_path):
    from calibration.dynamics.uncertainty import MISMATCH_SD

    twin = store.load("dynamics", "tw", calibrated)
    bus = _rec_with(calibrated, tmp_path, lambda r: r.meta.update(backend="dynamixel"))
    assert main(["calibrate", "dynamics", "--rig-id", "bus", "--dir", str(tmp_path),
                 "--recording", str(bus), "--no-report"]) == 0  # fmt: skip
    fitted = store.load("dynamics", "bus", tmp_path)
    for field in ("kp", "damping"):
        value = fitted["servos"][field][2]
        _, hi = np.asarray(fitted["intervals_95"][field])[2]
        # the same readings: about the same fit (a bus's readings are weighted for its
        # timing); the interval at least the mismatch's on that bus
        assert value == pytest.approx(twin["servos"][field][2], rel=1e-3)
        half = math.log(hi / value)
        assert half >= 1.959 * MISMATCH_SD["dynamixel"][field], (field, half)
        _, t_hi = np.asarray(twin["intervals_95"][field])[2]
        assert (
            math.log(t_hi / twin["servos"][field][2]) < half
        )  # the twin's own, without a mismatch, narrower
