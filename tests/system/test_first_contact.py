"""What a new user meets first: ``ergo --version``, the strategies in ``ergo explore --help``,
one name per meaning for ``--rig`` (the type) and ``--rig-id`` (the id), a goal-exploration
run refused on a rig that cannot see the ball, and a resume with nothing to do that leaves the
run folder as it was."""

from __future__ import annotations

import logging
import subprocess
import sys
from pathlib import Path

import pytest

from explore.cli import main, version
from explore.learner.strategies import STRATEGIES
from explore.rigs.rig import RigConfig, RigError
from explore.runs.config import RunConfig, StrategyConfig
from explore.runs.layout import COVERAGE_FILE, RECORDING_FILE
from explore.runs.lock import LOCK_FILE
from explore.runs.open_run import open_run

ERGO = [sys.executable, "-m", "explore.cli"]


def _cli(args: list[str], capsys) -> tuple[int | str | None, str, str]:
    try:
        code = main(args)
    except SystemExit as exc:  # argparse's own exits (--help, --version, bad flags)
        code = exc.code
    captured = capsys.readouterr()
    return code, captured.out, captured.err.strip()


def test_ergo_version_prints_the_installed_version(capsys):
    code, out, _ = _cli(["--version"], capsys)
    assert code == 0 and out.strip() == f"ergo-explore {version()}"
    assert version() != "unknown"  # installed by `make install` (pip install -e)


def test_explore_help_lists_every_strategy_with_what_it_is(capsys):
    code, out, _ = _cli(["explore", "--help"], capsys)
    assert code == 0
    listed = out[out.index("strategies (--strategy NAME):") :]
    for name in STRATEGIES:
        summary = STRATEGIES[name].summary
        assert summary and f"{name}" in listed and summary in " ".join(listed.split()), name


def test_calibrate_takes_the_rig_id_as_rig_id_and_refuses_rig_in_one_line(tmp_path, capsys):
    code, _, err = _cli(["calibrate", "show", "--rig", "bench", "--dir", str(tmp_path)], capsys)
    assert code == 2 and len(err.splitlines()) == 1
    assert "--rig-id" in err and "rig type" in err
    # the id goes where --rig-id says (show reports the files it looks for under that id)
    code, out, err = _cli(
        ["calibrate", "show", "--rig-id", "bench", "--dir", str(tmp_path)], capsys
    )
    assert str(tmp_path / "bench") in out + err


def _hardware_config(strategy: str) -> RunConfig:
    # a port that is never opened: open_run builds the rig, it does not connect it
    rig = RigConfig("dynamixel", "nocal", {"port": "/dev/null-ergo-test"})
    return RunConfig(rig=rig, strategy=StrategyConfig(strategy), episodes=2)


def test_goal_exploration_on_a_rig_without_arena_calibration_is_refused_with_the_command(
    tmp_path, monkeypatch
):
    monkeypatch.setenv("ERGO_CALIBRATION_DIR", str(tmp_path / "calibration"))
    out = tmp_path / "run"
    with pytest.raises(RigError) as caught:
        open_run(out, _hardware_config("rge-efr"), mode="new")
    message = str(caught.value)
    assert "\n" not in message and "cannot locate the ball" in message
    assert "ergo calibrate arena --rig-id nocal" in message
    assert not out.exists()  # nothing made


def test_random_exploration_on_that_rig_starts_with_one_warning(tmp_path, monkeypatch, caplog):
    monkeypatch.setenv("ERGO_CALIBRATION_DIR", str(tmp_path / "calibration"))
    with caplog.at_level(logging.WARNING), open_run(tmp_path / "run", _hardware_config("rpe")):
        pass
    warnings = [r for r in caplog.records if "no ball tracking" in r.getMessage()]
    assert len(warnings) == 1 and "ergo calibrate arena --rig-id nocal" in warnings[0].getMessage()


def test_a_resume_with_nothing_to_do_writes_no_new_recording(tmp_path):
    run = tmp_path / "run"
    base = ["explore", "--no-progress", "--rig-option", "render_size=[64,64]"]
    assert main([*base, "--episodes", "2", "--out", str(run)]) == 0
    # the writer lock names whoever opens the run (explore/runs/lock.py): not the run's data
    before = {p.name: p.stat().st_mtime_ns for p in run.iterdir() if p.name != LOCK_FILE}
    assert "recording.rrd" in before
    result = subprocess.run(
        [*ERGO, "explore", "--resume", str(run), "--no-progress"],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert "already 2 episodes" in result.stdout
    after = {p.name: p.stat().st_mtime_ns for p in run.iterdir() if p.name != LOCK_FILE}
    assert after == before  # nothing written


def test_the_readme_says_how_to_reach_ergo_after_make_run():
    readme = (Path(__file__).resolve().parents[2] / "README.md").read_text()
    assert "source .venv/bin/activate" in readme and ".venv/bin/ergo" in readme


def _readme_commands() -> list[str]:
    """Every ``ergo ...`` command of the README's sh blocks (continuations joined, comments and
    ``;`` split off), but those with placeholders (``...``, ``[runs/B ...]``)."""
    import re
    import shlex

    readme = (Path(__file__).resolve().parents[2] / "README.md").read_text()
    commands = []
    for block in re.findall(r"```sh\n(.*?)```", readme, re.S):
        for line in block.replace("\\\n", " ").splitlines():
            for part in line.split("#")[0].split(";"):
                words = shlex.split(part)
                if words[:1] == ["ergo"] and not any("..." in w for w in words):
                    commands.append(part.strip())
    return commands


def test_every_ergo_command_of_the_readme_parses_as_written():
    """Parsed by ``ergo``'s own parser (nothing is run): `ergo calibrate camera|arena|joints`
    did not."""
    import shlex

    from explore.cli import build_parser

    commands = _readme_commands()
    assert len(commands) > 20 and any(c.startswith("ergo calibrate joints") for c in commands)
    for command in commands:
        try:
            build_parser().parse_args(shlex.split(command)[1:])
        except SystemExit as exc:
            assert exc.code == 0, command  # --help


def _explore_spawn(out: Path, *extra: str) -> list[str]:
    return ["explore", "--rig", "sim", "--strategy", "rpe", "--episodes", "2", "--seed", "0",
            "--out", str(out), "--no-progress", *extra]  # fmt: skip


def test_rerun_spawn_finds_the_viewer_beside_python_without_path(tmp_path, monkeypatch, capsys):
    import rerun

    spawned = []
    monkeypatch.setattr(rerun, "spawn", lambda **kw: spawned.append(kw))  # no window here
    monkeypatch.setenv("PATH", "")  # .venv/bin/ergo run with the venv not activated
    monkeypatch.setenv("DISPLAY", ":0")
    out = tmp_path / "run"
    code, _, err = _cli(_explore_spawn(out, "--rerun", "spawn"), capsys)
    assert code == 0, err
    beside = Path(sys.executable).parent / "rerun"
    assert beside.is_file() and spawned[0]["executable_path"] == str(beside)
    assert (out / COVERAGE_FILE).is_file()


def test_rerun_spawn_without_a_viewer_fails_in_one_line_before_any_folder(
    tmp_path, monkeypatch, capsys
):
    import explore.report.recorder as recorder

    monkeypatch.setattr(recorder, "viewer_executable", lambda: None)
    monkeypatch.setenv("DISPLAY", ":0")
    out = tmp_path / "run"
    code, _, err = _cli(_explore_spawn(out, "--rerun", "spawn"), capsys)
    assert code == 2 and len(err.splitlines()) == 1 and "rerun viewer" in err
    assert not out.exists()  # nothing blocks the same --out
    assert _cli(_explore_spawn(out, "--rerun", "off"), capsys)[0] == 0


def test_rerun_spawn_without_a_display_saves_the_recording_and_the_coverage(
    tmp_path, monkeypatch, capsys
):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    out = tmp_path / "run"
    code, _, err = _cli(_explore_spawn(out, "--rerun", "spawn"), capsys)
    assert code == 0 and "no display here" in err
    assert (out / RECORDING_FILE).is_file() and (out / COVERAGE_FILE).is_file()


def test_the_coverage_figure_is_drawn_before_the_recording_is_closed(tmp_path, monkeypatch, capsys):
    """Closing a viewer's stream waited forever for a viewer that never came up (no display),
    and the user's Ctrl-C then left no coverage.png: it is drawn first now."""
    import explore.report.recorder as recorder

    def never_closes(self):
        raise KeyboardInterrupt  # the user giving up on a close that hangs

    monkeypatch.setattr(recorder.Recorder, "close", never_closes)
    out = tmp_path / "run"
    code, _, err = _cli(_explore_spawn(out, "--rerun", "save"), capsys)
    assert code != 0 and "interrupted" in err
    assert (out / COVERAGE_FILE).is_file()


@pytest.mark.parametrize(
    "args, hint",
    [
        (["explore", "--strategy", "rge-erf", "--episodes", "1"], "'rge-efr'"),
        (["experiment", "--strategies", "rpe,rge-erf", "--episodes", "1"], "'rge-efr'"),
        (["explore", "--rig", "simm"], "'sim'"),  # an argparse choice
        (["explre"], "'explore'"),  # a command
        (["explore", "--strategy", "rge-efr", "--strategy-option", "bootstrp=3"], "'bootstrap'"),
        (
            ["explore", "--strategy", "rge-efr", "--strategy-option", 'goals="unifrom"'],
            "'uniform'",
        ),
    ],
)
def test_a_mistyped_name_gets_did_you_mean_in_one_line(args, hint, tmp_path, capsys):
    out = tmp_path / "run"
    code, _, err = _cli([*args, "--out", str(out)], capsys)
    assert code == 2 and len(err.splitlines()) == 1
    assert f"(did you mean {hint}?)" in err
    assert not out.exists()


def test_no_hint_for_a_name_close_to_nothing(capsys):
    from plumbing.registry import did_you_mean

    assert did_you_mean("zzz", ["rpe", "rge-efr"]) == ""
    code, _, err = _cli(["explore", "--rig", "qqqq"], capsys)
    assert code == 2 and "did you mean" not in err


def test_the_emulated_bus_demo_report_says_why_its_cells_are_empty(tmp_path):
    """The README's hardware-in-the-loop demo without an arena calibration: its report counts
    0 ball and 0 end-effector cells, and says why and what to run (summary and stderr)."""
    serve = subprocess.Popen(
        [*ERGO, "twin", "serve", "--bus", "dynamixel"],
        stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
    )  # fmt: skip
    try:
        port = serve.stdout.readline().split()[-1]
        camera = serve.stdout.readline().split()[-1]
        run = tmp_path / "hil"
        explore = subprocess.run(
            [*ERGO, "explore", "--rig", "dynamixel", "--rig-id", "hil", "--port", port,
             "--camera", camera, "--episodes", "1", "--out", str(run), "--no-progress",
             "--rerun", "off"],
            capture_output=True, text=True, timeout=180,
        )  # fmt: skip
        assert explore.returncode == 0, explore.stderr[-2000:]
    finally:
        serve.terminate()
        serve.wait(timeout=30)
    report = subprocess.run(
        [*ERGO, "report", str(run)], capture_output=True, text=True, timeout=120
    )
    assert report.returncode == 0, report.stderr
    md = (run / "report" / "summary.md").read_text()
    assert "| ball cells reached | 0 of 900 |" in md
    assert "| end-effector cells reached | 0 of 900 |" in md
    for text in (md, report.stderr):
        assert "had no arena calibration" in text
        assert "`ergo calibrate arena --rig-id hil --camera ...`" in text
        assert "camera tracks the ball only" in text
