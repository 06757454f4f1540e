"""A run's fingerprint: equal for the same run however it was made (in one go, resumed; its
history's bytes differ by their wall times), different for another, in run.json when a session
ends, and shown by ``ergo runs fingerprint``."""

from __future__ import annotations

import json

import numpy as np

from explore.cli import main as ergo
from explore.rigs.rig import RigConfig
from explore.runs.config import RunConfig, StrategyConfig
from explore.runs.fingerprint import FINGERPRINT_KEY, canonical_array, fingerprint_run
from explore.runs.open_run import open_run


def _run(path, episodes, seed=1, strategy="rge-efr"):
    config = RunConfig(
        rig=RigConfig("arm2balls"),
        strategy=StrategyConfig(strategy, {"bootstrap": 5}),
        seed=seed,
        episodes=episodes,
    )
    with open_run(path, config, episodes=episodes) as run:
        return run.explore()


def test_the_same_run_made_in_one_go_or_resumed_has_one_fingerprint(tmp_path, capsys):
    whole = _run(tmp_path / "a", 60)
    _run(tmp_path / "b", 25)
    resumed = _run(tmp_path / "b", 60)  # the same folder, resumed to 60
    other = _run(tmp_path / "c", 60, seed=2)
    assert (tmp_path / "a/history.bin").read_bytes() != (tmp_path / "b/history.bin").read_bytes()
    digest = whole.fingerprint.hexdigest()
    assert resumed.fingerprint.hexdigest() == digest != other.fingerprint.hexdigest()
    for name in "ab":  # run.json keeps it; the history gives it again
        meta = json.loads((tmp_path / name / "run.json").read_text())
        assert meta[FINGERPRINT_KEY] == {"sha256": digest, "episodes": 60, "version": 1}
        assert fingerprint_run(tmp_path / name).fingerprint.hexdigest() == digest
    assert ergo(["runs", "fingerprint", str(tmp_path / "a"), str(tmp_path / "b")]) == 0
    out = capsys.readouterr().out
    assert f"{digest}  {tmp_path / 'a'}: 60 episodes," in out and "the same run" in out
    assert ergo(["runs", "fingerprint", str(tmp_path / "a"), str(tmp_path / "c")]) == 1
    assert "2 different runs" in capsys.readouterr().out
    assert ergo(["runs", "fingerprint", str(tmp_path / "nowhere")]) == 2
    assert "ergo: error:" in capsys.readouterr().err


def test_canonical_arrays_write_every_nan_alike_and_name_their_shape():
    a = np.array([1.0, np.nan, -np.nan])
    b = np.array([1.0, np.nan, np.nan])
    b[2] = np.frombuffer(np.uint64(0xFFF8000000000001).tobytes(), dtype=float)[0]  # a payload
    assert canonical_array(a) == canonical_array(b)
    assert canonical_array(np.zeros((2, 3))) != canonical_array(np.zeros((3, 2)))
    assert canonical_array(np.zeros(0)) != canonical_array(np.zeros((0, 2)))
