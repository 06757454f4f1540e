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
    assert len(warnings) == 1 and warnings[0].getMessage() == (
        f"no ball tracking for rig 'nocal' (no calibration file {tmp_path}/calibration/nocal/"
        "arena.json): this run will count 0 ball cells; run 'ergo calibrate arena --rig-id "
        "nocal --camera ...' first (docs/calibration.md)"
    )


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


# Terms the README uses, and the words that say what each is: they must come near its first use
# (a newcomer reads on, and no term is left for a search engine).
README_TERMS = {
    "MuJoCo": "physics engine",
    "EGL": "OpenGL without a window",
    "ChArUco": "a chessboard with an ArUco marker",
    "ArUco": "a square code OpenCV finds and",
    "rig id": "names one arm and its camera",
    "Ray": "spreads Python work over a cluster",
    "learning progress": "how fast the arm gets better at reaching",
    "Arm-2-Balls": "a simulated 2-D arm",
    "700-707": "kept apart while the code was developed",
    "CiA 402": "CANopen's drive profile",
    "DMP": "dynamic movement primitive",
    "pty": "a virtual serial port",
}
NEAR = 400  # characters: the definition is in the term's sentence or the next one


@pytest.mark.parametrize("term, definition", README_TERMS.items(), ids=list(README_TERMS))
def test_the_readme_says_what_each_term_is_where_it_first_uses_it(term, definition):
    import re

    readme = (Path(__file__).resolve().parents[2] / "README.md").read_text()
    text = " ".join(readme.split())  # lines joined: a definition may wrap
    first = re.search(rf"(?<![\w-]){re.escape(term)}(?![\w-])", text, re.I)
    assert first, term
    said = text.find(" ".join(definition.split()), max(0, first.start() - NEAR))
    assert said >= 0 and abs(said - first.start()) <= NEAR, (term, text[first.start() :][:200])


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


def _readme_served_twin_commands() -> list[str]:
    """The README's commands for a run on the served twin, in order (``ergo twin serve``, the
    arena's calibration, the run), with its placeholders ``N`` and ``P`` as written."""
    block = next(b for b in _readme_sh_blocks() if "ergo twin serve --bus dynamixel" in b)
    return [line.split("#")[0].strip() for line in block.splitlines() if line.startswith("ergo ")]


def _readme_sh_blocks() -> list[str]:
    import re

    readme = (Path(__file__).resolve().parents[2] / "README.md").read_text()
    return re.findall(r"```sh\n(.*?)```", readme, re.S)


def test_the_emulated_bus_demo_counts_ball_cells_once_calibrated_as_the_readme_says(
    tmp_path, monkeypatch
):
    """The README's hardware-in-the-loop demo. Without the arena calibration its report counts
    0 ball and 0 end-effector cells and says why and what to run (summary and stderr); with the
    README's calibration line first, the same run counts the ball."""
    import shlex

    monkeypatch.setenv("ERGO_CALIBRATION_DIR", str(tmp_path / "calibration"))  # subprocesses too
    serve_cmd, calibrate_cmd, explore_cmd = _readme_served_twin_commands()[:3]
    assert serve_cmd == "ergo twin serve --bus dynamixel"
    assert calibrate_cmd.startswith("ergo calibrate arena --rig-id hil")
    assert explore_cmd.startswith("ergo explore --rig dynamixel --rig-id hil")
    log = tmp_path / "serve.log"  # what the server said, shown if it does not start
    with log.open("w") as server_stderr:
        serve = subprocess.Popen(
            [*ERGO, *shlex.split(serve_cmd)[1:]],
            stdout=subprocess.PIPE, stderr=server_stderr, text=True,
        )  # fmt: skip
    try:
        first = serve.stdout.readline()
        assert first.startswith("dynamixel bus on "), (first, log.read_text()[-2000:])
        port = first.split()[-1]  # dynamixel bus on /dev/pts/N
        camera = serve.stdout.readline().split()[-1]  # camera on URL
        url = "http://127.0.0.1:P/stream.mjpg"
        assert camera.endswith("/stream.mjpg") and url in explore_cmd and url in calibrate_cmd

        def typed(command: str, *extra: str) -> subprocess.CompletedProcess:
            words = shlex.split(command.replace("/dev/pts/N", port).replace(url, camera))
            return subprocess.run(
                [*ERGO, *words[1:], *extra], capture_output=True, text=True, timeout=180
            )

        quick = ["--episodes", "1", "--no-progress", "--rerun", "off"]
        blind = tmp_path / "blind"
        explore = typed(explore_cmd, *quick, "--out", str(blind))
        assert explore.returncode == 0, explore.stderr[-2000:]
        assert "this run will count 0 ball cells" in explore.stderr
        assert explore.stdout.strip().endswith("1 episodes, 0 ball cells reached")
        calibrate = typed(calibrate_cmd)
        assert calibrate.returncode == 0, calibrate.stderr[-2000:]
        seen = tmp_path / "seen"
        explore = typed(explore_cmd, *quick, "--out", str(seen))
        assert explore.returncode == 0, explore.stderr[-2000:]
        assert "no ball tracking" not in explore.stderr
        assert not explore.stdout.strip().endswith(" 0 ball cells reached"), explore.stdout
    finally:
        serve.terminate()
        serve.wait(timeout=30)
    report = subprocess.run(
        [*ERGO, "report", str(blind)], capture_output=True, text=True, timeout=120
    )
    assert report.returncode == 0, report.stderr
    md = (blind / "report" / "summary.md").read_text()
    assert "| ball cells reached | 0 of 900 |" in md
    assert "| end-effector cells reached | 0 of 900 |" in md
    for text in (md, report.stderr):
        assert "had no arena calibration" in text
        assert "`ergo calibrate arena --rig-id hil --camera ...`" in text
        assert "camera tracks the ball only" in text


# ---- the newcomer's mistakes: one line naming the flag and the near miss ---------------------
def _strategies_line(typed: str) -> str:
    return (
        f"ergo: error: --strategy must be one of {', '.join(sorted(STRATEGIES))}, got "
        f"{typed!r} (did you mean 'rge-efr'?)"
    )


@pytest.mark.parametrize("typed", ["rge-erf", "RGE-EFR"])
def test_a_mistyped_strategy_names_the_flag_and_the_strategy_meant(typed, tmp_path, capsys):
    out = tmp_path / "run"
    code, _, err = _cli(
        ["explore", "--strategy", typed, "--episodes", "1", "--out", str(out)], capsys
    )
    assert code == 2 and err == _strategies_line(typed)
    assert not out.exists()


def test_a_bad_option_of_a_new_run_is_named_by_its_flag(tmp_path, capsys):
    out = tmp_path / "run"
    code, _, err = _cli(
        ["explore", "--rig-option", "render_sise=[64,64]", "--out", str(out)], capsys
    )
    assert code == 2 and err.startswith(
        "ergo: error: --rig-option render_sise is unknown (did you mean 'render_size'?); known: "
    )
    code, _, err = _cli(["explore", "--seed", "-3", "--out", str(out)], capsys)
    assert err == "ergo: error: --seed must be an integer in [0, 2**63-1], got -3"
    assert not out.exists()


def test_a_near_miss_of_a_run_folder_gets_the_run_meant(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "runs" / "rge-efr-s0").mkdir(parents=True)
    (tmp_path / "runs" / "rge-efr-s0" / "run.json").write_text("{}")  # what marks a run folder
    (tmp_path / "runs" / "rge-efr-s").with_name("rge-efr-sx").mkdir()  # not a run: not offered
    code, _, err = _cli(["explore", "--resume", "runs/rge-efr-s", "--episodes", "2"], capsys)
    assert code == 2 and err == (
        "ergo: error: --resume runs/rge-efr-s: no such run folder (did you mean 'runs/rge-efr-s0'?)"
    )
    for args in (["replay", "runs/rge-efr-s"], ["runs", "check", "runs/rge-efr-s"],
                 ["export", "lerobot", "runs/rge-efr-s", "--out", "datasets/x"]):  # fmt: skip
        code, _, err = _cli(args, capsys)
        assert code == 2 and err == (
            "ergo: error: runs/rge-efr-s: no such run folder (did you mean 'runs/rge-efr-s0'?)"
        ), args
    code, _, err = _cli(["explore", "--resume", "runs/zzzz"], capsys)
    assert err == "ergo: error: --resume runs/zzzz: no such run folder"  # nothing near
    assert sorted(p.name for p in (tmp_path / "runs").iterdir()) == ["rge-efr-s0", "rge-efr-sx"]
    assert not (tmp_path / "datasets").exists()


def test_a_strategy_without_its_model_names_the_flag_that_gives_it(tmp_path, capsys):
    from explore.learner.strategies.registry import SAE, VAE

    for strategy, model in (("rge-vae", VAE), ("mge-sae", SAE)):
        out = tmp_path / strategy
        code, _, err = _cli(["explore", "--strategy", strategy, "--out", str(out)], capsys)
        assert code == 2 and err == (
            f"ergo: error: --strategy {strategy} needs {model.what}: give --strategy-option "
            f"{model.option}=PATH (make one with: {model.recipe})"
        )
        assert not out.exists()


@pytest.mark.parametrize(
    "interfaces, hint",
    [
        (
            {"lo": 772, "eth0": 1, "can0": 280, "vcan1": 280},
            " (no CAN interface 'can9': this machine has can0, vcan1 (did you mean "
            "socketcan:can0?); bring one up with: sudo ip link set can0 up type can bitrate "
            "1000000)",
        ),
        (
            {"lo": 772, "eth0": 1},
            " (no CAN interface 'can9': this machine has none; is the adapter plugged in and its "
            "driver loaded? `ip link` lists them; a USB adapter that speaks SLCAN is "
            "slcan:/dev/ttyACM0)",
        ),
        ({"can9": 280}, " (is can9 up? sudo ip link set can9 up type can bitrate 1000000)"),
    ],
    ids=["others", "none", "down"],
)
def test_a_socketcan_channel_that_fails_names_the_can_interfaces_there(
    interfaces, hint, tmp_path, capsys, monkeypatch
):
    """The hint names what this machine has (``/sys/class/net``, type 280 = ``ARPHRD_CAN``),
    not a fixed ``can0``."""
    import errno

    import can

    import robot.canopen.bus as can_bus

    net = tmp_path / "net"
    net.mkdir()
    for name, kind in interfaces.items():
        (net / name).mkdir()
        (net / name / "type").write_text(f"{kind}\n")
    monkeypatch.setattr(can_bus, "SYS_CLASS_NET", net)

    def no_such_device(**kwargs):
        raise OSError(errno.ENODEV, "No such device")

    monkeypatch.setattr(can, "Bus", no_such_device)
    code, _, err = _cli(["bus", "scan", "--can", "socketcan:can9"], capsys)
    assert code == 2 and err == (
        "ergo: error: cannot open CAN bus socketcan:can9: [Errno 19] No such device" + hint
    )


def test_an_export_without_video_says_how_to_keep_the_frames(tmp_path, capsys):
    pytest.importorskip("pyarrow")
    pytest.importorskip("av")
    run = tmp_path / "run"
    assert _cli([*_explore_spawn(run, "--rerun", "off"), "--rig-option", "render_size=[64,64]"],
                capsys)[0] == 0  # fmt: skip
    code, out, err = _cli(["export", "lerobot", str(run), "--out", str(tmp_path / "ds")], capsys)
    assert code == 0, err
    assert out.splitlines()[-1] == (
        f"{tmp_path / 'ds'}: LeRobotDataset v3.0, 2 episodes, 80 frames, 1 tasks, no video: the "
        "runs kept no camera frames (explore with --rig-option record_video=128 to keep them; "
        "docs/ecosystem.md)"
    )
    code, out, _ = _cli(
        ["export", "lerobot", str(run), "--out", str(tmp_path / "ds2"), "--no-video"], capsys
    )
    assert code == 0 and out.splitlines()[-1].endswith(", no video (--no-video)")
