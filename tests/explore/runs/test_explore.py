"""Exploration runs: determinism, crash safety and resume, the metric, the CLI."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from explore.cli import main
from explore.learner.strategies.goal_exploration import STALL_WINDOW
from explore.rigs.arena import TWIN_ARENA
from explore.runs.layout import COVERAGE_FILE, FAULTS_FILE, HISTORY_FILE, METRICS_FILE
from explore.runs.metrics import CellCounter, read_metrics
from explore.runs.store import RunStore

N = 50


def ergo(*args: str) -> int:
    return main([*args, "--no-progress"]) if args[0] == "explore" else main(list(args))


@pytest.fixture(scope="module")
def reference_run(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("ref") / "run"
    assert ergo("explore", "--episodes", str(N), "--seed", "3", "--out", str(out)) == 0
    return out


def histories_equal(a: Path, b: Path) -> bool:
    ra, rb = RunStore.open(a).records, RunStore.open(b).records
    return len(ra) == len(rb) and all(x.equals(y) for x, y in zip(ra, rb, strict=True))


def test_rpe_run_is_deterministic_for_a_seed(reference_run, tmp_path):
    assert ergo("explore", "--episodes", str(N), "--seed", "3", "--out", str(tmp_path / "b")) == 0
    assert histories_equal(reference_run, tmp_path / "b")
    other = tmp_path / "c"
    assert ergo("explore", "--episodes", "5", "--seed", "4", "--out", str(other)) == 0
    assert not np.array_equal(
        RunStore.open(other).records[0].theta, RunStore.open(reference_run).records[0].theta
    )


def test_a_run_writes_history_metrics_and_a_coverage_curve(reference_run):
    assert (reference_run / HISTORY_FILE).stat().st_size > 0
    m = read_metrics(reference_run / METRICS_FILE)
    assert list(m["episode"]) == list(range(N))
    assert np.all(np.diff(m["ball_cells"]) >= 0) and m["ball_cells"][-1] >= 1
    assert (reference_run / COVERAGE_FILE).stat().st_size > 1000
    rec = RunStore.open(reference_run).records[0]
    assert rec.image.shape == (64, 64, 3) and rec.image.dtype == np.uint8
    assert rec.targets.shape == (40, 6) and rec.end_effector.shape == (40, 3)


def test_a_run_killed_with_sigkill_resumes_to_the_same_history(
    reference_run, tmp_path, explore_killed_at
):
    out = tmp_path / "killed"
    # kill at some point in the middle of the run (several records written)
    explore_killed_at(["--episodes", str(N), "--seed", "3", "--no-progress"], out, 60_000)
    done = len(RunStore.open(out))
    assert 0 < done < N, f"kill landed outside the run ({done} episodes)"
    assert ergo("explore", "--resume", str(out)) == 0
    assert histories_equal(reference_run, out)
    m = read_metrics(out / METRICS_FILE)
    assert list(m["episode"]) == list(range(N))  # metrics rebuilt, nothing duplicated


def test_resume_can_extend_a_run_and_refuses_to_change_its_config(tmp_path, capsys):
    out = tmp_path / "r"
    assert ergo("explore", "--episodes", "3", "--out", str(out), "--resume-or-new") == 0
    assert ergo("explore", "--episodes", "5", "--out", str(out), "--resume-or-new") == 0
    assert len(RunStore.open(out)) == 5
    assert ergo("explore", "--resume", str(out), "--seed", "9") == 2
    assert "--seed 9 differs" in capsys.readouterr().err


def test_strategy_options_are_stored_and_kept_on_resume(tmp_path, capsys):
    out = tmp_path / "s"
    args = ["explore", "--strategy", "rge-efr", "--episodes", "4", "--out", str(out)]
    assert ergo(*args, "--strategy-option", "bootstrap=2", "--rerun", "off") == 0
    store = RunStore.open(out)
    # as given, and the option whose default changed written out (test_changed_defaults.py)
    assert store.config["strategy"]["options"] == {"bootstrap": 2, "stall_window": STALL_WINDOW}
    kinds = [r.kind for r in store.records]
    assert kinds[:2] == ["random", "random"] and set(kinds[2:]) - {"random"}, kinds
    assert ergo(*args, "--strategy-option", "bootstrap=2", "--resume-or-new") == 0  # the same
    assert ergo("explore", "--resume", str(out), "--strategy-option", "bootstrap=3") == 2
    assert "keeps the strategy options" in capsys.readouterr().err
    assert ergo("explore", "--out", str(tmp_path / "t"), "--strategy", "rge-efr",
                "--strategy-option", "nonsense=1", "--episodes", "1") == 2  # fmt: skip
    assert "nonsense" in capsys.readouterr().err and not (tmp_path / "t").exists()


def test_the_outcome_is_observed_with_the_arm_back_at_rest():
    """The arm lags its last rest command by 1-2 degrees, a few pixels of the 64x64 outcome
    image (more than a ball moved by a centimetre): the outcome waits until it has stopped."""
    from explore.rigs.arm_episodes import EpisodeRunner
    from explore.rigs.rig import RigConfig, make_rig

    with make_rig(RigConfig()) as rig:
        runner = EpisodeRunner(rig)
        runner.go_rest()
        context = runner.observe(render=False)
        rest = rig.arm.spec.rest
        for seed in range(4):
            theta = np.random.default_rng(seed).uniform(-1, 1, 48)
            result = runner.run(theta, context)
            assert np.array_equal(rig.arm.last_sent, rest)
            assert np.abs(rig.sensor.twin.joint_positions() - rest).max() < np.radians(0.3)
            assert not np.allclose(result.targets[-1], rest, atol=0.05)  # it did move
            rig.clock.advance(1.0)  # a second later the scene is the same
            later = runner.observe(render=True).image
            change = np.abs(later.astype(int) - result.outcome.image.astype(int)).mean()
            assert change < 0.1, f"episode {seed}: the outcome image changed by {change:.2f}"
            context = result.outcome
        t = rig.sensor.twin.time
        runner.go_rest()  # already there: nothing is sent, no time passes
        assert rig.sensor.twin.time == t


def test_a_reading_that_flickers_by_one_servo_unit_does_not_hold_the_settle(monkeypatch):
    """A real XL-320 at rest can read one unit (0.29 degrees) apart from one check to the
    next, just over what arm_settle_speed allows in a check: that is not motion."""
    from explore.rigs.arm_episodes import EpisodeRunner
    from explore.rigs.rig import RigConfig, make_rig
    from sim.arm import SimArm

    unit = np.radians(300.0 / 1023.0)  # XL-320 position unit (e-manual)
    monkeypatch.setattr(SimArm, "position_resolution", property(lambda self: np.full(6, unit)))
    with make_rig(RigConfig()) as rig:
        runner = EpisodeRunner(rig)
        runner.go_rest()
        rig.clock.advance(1.0)  # the arm has stopped at rest
        true_read, calls = rig.arm.read, [0]

        def flickering_read():
            state = true_read()
            calls[0] += 1
            q = np.round(state.positions / unit) * unit
            q[2] += unit * (calls[0] % 2)  # joint 3 reads one unit higher every other time
            state.positions = q
            return state

        rig.arm.read = flickering_read
        assert runner.settle() == pytest.approx(runner.config.settle_check_s)
        monkeypatch.setattr(SimArm, "position_resolution", property(lambda self: np.zeros(6)))
        assert runner.settle() == pytest.approx(runner.config.settle_max_s)  # the old rule


def test_ball_reset_start_puts_the_ball_back_before_every_episode(tmp_path, capsys):
    out = tmp_path / "reset"
    args = ["explore", "--episodes", "25", "--seed", "1", "--out", str(out), "--rerun", "off"]
    assert ergo(*args, "--rig-option", "ball_reset=start") == 0
    recs = RunStore.open(out).records
    contexts = np.array([r.context_ball for r in recs])
    assert np.allclose(contexts, contexts[0], atol=1e-6), contexts  # the same every episode
    assert any(r.ball_moved for r in recs)  # while the arm did push it away in some
    bad = ["explore", "--episodes", "1", "--out", str(tmp_path / "b"), "--rig-option"]
    assert ergo(*bad, "ball_reset=sometimes") == 2
    err = capsys.readouterr().err
    assert "--rig-option ball_reset must be one of 'none', 'start', got 'sometimes'" in err


def test_cell_counter_on_hand_made_points():
    c = CellCounter(half_width=0.2, n_bins=30)  # cells of 0.4/30 m
    w = 0.4 / 30
    pts = np.array([
        [0.0, 0.0], [w / 3, w / 3],  # the same cell
        [-0.2, -0.2],  # first cell
        [0.2, 0.2],  # the far corner belongs to the last cell
        [0.25, 0.0],  # outside: ignored
        [np.nan, 0.1],  # not seen: ignored
        [-0.2 + w, -0.2],  # the next cell along x
    ])  # fmt: skip
    assert c.add(pts) == 4
    assert c.add(np.array([0.0, 0.0])) == 4  # already counted
    idx = c.cells_of(np.array([[-0.2, -0.2], [0.2 - 1e-9, 0.0]]))
    assert idx.tolist() == [[0, 0], [29, 15]]


@pytest.mark.parametrize(
    "args, message",
    [
        (["explore", "--episodes", "0"], "--episodes must be at least 1"),
        (["explore", "--strategy", "nope", "--episodes", "1"], "--strategy must be one of"),
        (["explore", "--bogus"], "unrecognized arguments: --bogus"),
        (["explore", "--rig", "sim", "--rig-option", "novalue"], "expected KEY=VALUE"),
    ],
)
def test_bad_flags_get_a_one_line_error(args, message, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    try:
        code = main(args)
    except SystemExit as exc:  # argparse's own errors
        code = exc.code
    assert code == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1, err
    assert not (tmp_path / "runs").exists()  # nothing half-made left behind


def test_every_command_has_help(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    for command in ("explore", "sim", "twin", "bus"):
        assert command in out


def test_fault_counters_are_summed_per_session_and_never_mask_the_runs_error(tmp_path):
    import json

    from explore.learner.strategies import make_strategy
    from explore.rigs.rig import RigConfig, make_rig
    from explore.runs.config import RunConfig
    from explore.runs.explorer import add_fault_counts
    from explore.runs.open_run import open_run

    assert add_fault_counts(tmp_path, {"bus_retries": 2, "recovery_s": 0.5})["bus_retries"] == 2
    totals = add_fault_counts(tmp_path, {"bus_retries": 3, "links_lost": 1})
    assert totals == {"bus_retries": 5.0, "recovery_s": 0.5, "links_lost": 1.0}
    assert json.loads((tmp_path / FAULTS_FILE).read_text())["sessions"] == 2
    (tmp_path / FAULTS_FILE).write_text("{not json")  # a damaged file is kept aside
    assert add_fault_counts(tmp_path, {"bus_retries": 1}) == {"bus_retries": 1.0}
    assert (tmp_path / "faults.json.bad").read_text() == "{not json"

    rig = make_rig(RigConfig())
    strategy = make_strategy("rpe", scene=TWIN_ARENA)

    def broken_counts() -> dict[str, float]:
        raise RuntimeError("counters unreadable")

    def failing_propose(context, rng):
        raise ValueError("the strategy failed")

    rig.arm.fault_counts = broken_counts  # type: ignore[method-assign]
    strategy.propose = failing_propose  # type: ignore[method-assign]
    with (
        open_run(tmp_path / "run", RunConfig(episodes=3), rig=rig, strategy=strategy) as run,
        pytest.raises(ValueError, match="the strategy failed"),
    ):
        run.explore()
    assert not (tmp_path / "run" / FAULTS_FILE).exists()
