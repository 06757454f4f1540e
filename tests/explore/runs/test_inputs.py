"""``run.json`` records the input files a run used (a physical rig's calibration files, a learned
strategy's goal-space model) with their SHA-256, and a resume refuses, in one line naming what
changed and the override, a run whose inputs changed; an older ``run.json`` without the record
still resumes and gets one."""

from __future__ import annotations

import json

import numpy as np
import pytest

from calibration import store
from calibration.joints import JointCalibration
from explore.rigs.rig import RigConfig, make_rig
from explore.runs.config import RunConfig, StrategyConfig
from explore.runs.inputs import ALLOW_FLAG, InputsChanged, check_inputs, record_inputs
from explore.runs.layout import RUN_FILE
from explore.runs.open_run import open_run
from explore.runs.store import RunStore
from robot.spec import ergo_jr_spec

SPEC = ergo_jr_spec()


def joints(limit: float = 1.0) -> dict:
    n = SPEC.n
    return JointCalibration(
        tuple(SPEC.names), np.zeros(n), np.ones(n), np.full(n, -limit), np.full(n, limit)
    ).to_dict()


def physical(rig_id: str = "bench", strategy: StrategyConfig | None = None) -> RunConfig:
    rig = RigConfig("dynamixel", rig_id, {"port": "/dev/pts/99", "camera": "0"})
    return RunConfig(rig=rig, strategy=strategy or StrategyConfig("rpe"), episodes=5)


def new_store(tmp_path, config: RunConfig) -> RunStore:
    store_ = RunStore.create(tmp_path / "run", config.to_dict())
    record_inputs(store_, config)
    return store_


def test_run_json_records_each_calibration_file_with_its_hash(tmp_path):
    joints_path = store.save("joints", "bench", joints())
    config = physical()
    run = new_store(tmp_path, config)
    recorded = json.loads((run.path / RUN_FILE).read_text())["inputs"]
    assert recorded == [
        {
            "kind": "joints",
            "path": str(joints_path.resolve()),
            "sha256": store.file_sha256(joints_path),
        }
    ]
    assert check_inputs(run, config) is None  # nothing changed


def test_a_resume_after_a_recalibration_is_refused_naming_the_file_and_the_override(tmp_path):
    path = store.save("joints", "bench", joints(1.0))
    config = physical()
    run = new_store(tmp_path, config)
    before = (run.path / RUN_FILE).read_text()
    store.save("joints", "bench", joints(0.5))  # recalibrated
    with pytest.raises(InputsChanged) as caught:
        check_inputs(run, config)
    message = str(caught.value)
    assert f"joints {path.resolve()} changed (sha256 " in message and ALLOW_FLAG in message
    assert "\n" not in message and (run.path / RUN_FILE).read_text() == before
    # a calibration made after the run started is a change too
    store.save("joints", "bench", joints(1.0))
    arena = store.calibration_path("arena", "bench")
    arena.write_text("{}")
    with pytest.raises(InputsChanged, match=r"arena .*arena.json appeared"):
        check_inputs(run, config)
    arena.unlink()
    assert check_inputs(run, config) is None  # restored: the same bytes, the same hash
    # told to: the resume goes on, run.json keeps the old record
    store.save("joints", "bench", joints(0.5))
    note = check_inputs(run, config, allow_changed=True)
    assert note and "changed input files" in note
    meta = json.loads((run.path / RUN_FILE).read_text())
    assert meta["inputs"][0]["sha256"] == store.file_sha256(path)
    assert meta["inputs_before"][0]["until_episode"] == 0
    assert check_inputs(run, config) is None


def test_a_resume_with_a_retrained_model_is_refused(tmp_path):
    """The goal-space model's files (weights and config) are inputs too (issue 29)."""
    model = tmp_path / "models" / "sae"
    model.mkdir(parents=True)
    (model / "sae.pt").write_bytes(b"weights-1")
    (model / "sae.json").write_text('{"latent": 8}')
    config = RunConfig(strategy=StrategyConfig("rge-sae", {"sae": str(model / "sae.pt")}))
    run = new_store(tmp_path, config)
    kinds = [(e["kind"], e["path"]) for e in run.meta["inputs"]]
    assert kinds == [("model", str(model / "sae.pt")), ("model", str(model / "sae.json"))]
    (model / "sae.pt").write_bytes(b"weights-2")  # retrained
    with pytest.raises(
        InputsChanged, match=r"model sae.pt .* changed \(sha256 [0-9a-f]{12} ->"
    ) as info:
        check_inputs(run, config)
    assert ALLOW_FLAG in str(info.value) and "\n" not in str(info.value)  # the override, 1 line


def test_an_older_run_json_without_the_record_resumes_and_gets_one(tmp_path):
    store.save("joints", "bench", joints())
    config = physical()
    run = RunStore.create(tmp_path / "run", config.to_dict())  # as before the record existed
    assert "inputs" not in json.loads((run.path / RUN_FILE).read_text())
    note = check_inputs(run, config)
    assert note and "no record of its input files" in note
    assert len(json.loads((run.path / RUN_FILE).read_text())["inputs"]) == 1
    assert check_inputs(run, config) is None


def test_open_run_records_and_checks_the_inputs(tmp_path):
    """Through ``open_run``, as ``ergo explore`` opens runs (the rig built, not connected)."""
    store.save("joints", "bench", joints())
    config = physical()
    path = tmp_path / "run"
    open_run(path, config, mode="new").close()
    assert json.loads((path / RUN_FILE).read_text())["inputs"][0]["kind"] == "joints"
    store.save("joints", "bench", joints(0.7))
    with pytest.raises(InputsChanged, match=ALLOW_FLAG):
        open_run(path, mode="resume")
    with open_run(path, mode="resume", allow_changed_inputs=True) as run:
        assert any("changed input files" in n for n in run.notes())
        assert run.rig.arm.spec.upper[0] == pytest.approx(0.7)  # the new calibration applies
    assert make_rig(config.rig).arm.spec.upper[0] == pytest.approx(0.7)
