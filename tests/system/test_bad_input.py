"""Bad input: hand-edited, foreign or old run folders, calibration files and CLI flags give one
line naming the field and what was expected, and leave every file's bytes as they were."""

from __future__ import annotations

import copy
import json
import shutil
from pathlib import Path

import pytest

from explore.cli import main
from explore.runs.config import RunConfig, RunConfigError
from explore.runs.layout import RUN_FILE

RIG_OPTION = "render_size=[64,64]"


def _bytes_of(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir()) if p.is_file()}


def _run_cli(args: list[str], capsys) -> tuple[int | str | None, str]:
    try:
        code = main(args)
    except SystemExit as exc:  # argparse's own errors
        code = exc.code
    return code, capsys.readouterr().err.strip()


@pytest.fixture(scope="module")
def good_run(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("good") / "run"
    assert main(["explore", "--episodes", "2", "--out", str(out), "--no-progress",
                 "--rig-option", RIG_OPTION]) == 0  # fmt: skip
    return out


@pytest.fixture
def good_config(good_run) -> dict:
    return json.loads((good_run / RUN_FILE).read_text())["config"]


# ---- RunConfig.from_dict -------------------------------------------------------------------
def _set(cfg: dict, path: str, value) -> dict:
    cfg = copy.deepcopy(cfg)
    keys = path.split(".")
    node = cfg
    for k in keys[:-1]:
        node = node[k]
    if value is _DEL:
        del node[keys[-1]]
    else:
        node[keys[-1]] = value
    return cfg


_DEL = object()

BAD_FIELDS = [
    ("seed", "abc", "config.seed", "integer"),
    ("seed", -1, "config.seed", "integer"),
    ("seed", True, "config.seed", "integer"),
    ("seed", 1.5, "config.seed", "integer"),
    ("episodes", 0, "config.episodes", ">= 1"),
    ("episodes", "300", "config.episodes", "integer"),
    ("episodes", _DEL, "config.episodes", "integer"),
    ("rig", _DEL, "config.rig", "missing"),
    ("rig", "sim", "config.rig", "object"),
    ("rig.name", "ur5", "config.rig.name", "one of"),
    ("rig.rig_id", "", "config.rig.rig_id", "non-empty"),
    ("rig.options", [], "config.rig.options", "object"),
    ("rig.options.render_size", 240, "config.rig.options.render_size", "[height, width]"),
    ("rig.options.render_size", [0, 64], "config.rig.options.render_size", "[height, width]"),
    (
        "rig.options.render_sise",
        [64, 64],
        "config.rig.options.render_sise",
        "unknown (did you mean 'render_size'?); known",
    ),
    ("rig.options.baud", 1000000, "config.rig.options.baud", "unknown; known"),  # on the twin
    ("strategy.name", "curiosity", "config.strategy.name", "one of"),
    ("strategy.options", None, "config.strategy.options", "object"),
    ("strategy.options.bootstrap", 5, "config.strategy.options.bootstrap", "unknown; known"),
    ("bogus", 1, "config.bogus", "unknown; known"),
    ("episode.rate_hz", "40", "config.episode.rate_hz", "number"),
    ("episode.rate_hz", float("nan"), "config.episode.rate_hz", "number"),
    ("episode.reset_s", -1.0, "config.episode.reset_s", "number in"),
    ("episode.obs_size", 64.0, "config.episode.obs_size", "integer"),
    ("episode.bogus", 1, "config.episode.bogus", "unknown"),
]


# A Dynamixel rig's options, checked against that rig's own Options.
BAD_DYNAMIXEL_OPTIONS = [
    ("baud", "fast", "positive integer"),
    ("baud", 0, "positive integer"),
    ("port", 3, "string"),
    ("camera", -1, "device index"),
    ("camera", 1.5, "device index"),
    ("directions", "up", "list"),
]


def _check(config: dict, path: str, value, field: str, expected: str) -> None:
    bad = _set(config, path, value)
    with pytest.raises(RunConfigError) as exc:
        RunConfig.from_dict(bad, where="runs/x/run.json")
    msg = str(exc.value)
    assert msg.startswith("runs/x/run.json: field '" + field + "'"), msg
    assert expected in msg and "\n" not in msg, msg


@pytest.mark.parametrize("path, value, field, expected", BAD_FIELDS)
def test_a_bad_run_config_names_the_field_in_one_line(good_config, path, value, field, expected):
    _check(good_config, path, value, field, expected)


@pytest.mark.parametrize("key, value, expected", BAD_DYNAMIXEL_OPTIONS)
def test_a_rigs_options_are_checked_against_that_rig(good_config, key, value, expected):
    config = _set(good_config, "rig", {"name": "dynamixel", "options": {"port": "/dev/pts/3"}})
    _check(config, f"rig.options.{key}", value, f"config.rig.options.{key}", expected)


def test_the_run_config_accepts_what_ergo_explore_writes_and_gives_it_back(good_config):
    assert RunConfig.from_dict(good_config).to_dict() == good_config
    opts = {"port": "/dev/pts/3", "baud": 1000000, "camera": "http://127.0.0.1:1/s"}
    hardware = _set(good_config, "rig", {"name": "dynamixel", "rig_id": "x", "options": opts})
    assert RunConfig.from_dict(hardware).rig.options == opts  # stored as given


def test_a_run_config_that_is_not_an_object_is_refused():
    with pytest.raises(RunConfigError, match="field 'config' must be an object"):
        RunConfig.from_dict([1, 2])


# ---- edited run folders through the CLI ----------------------------------------------------
def _edited(good_run: Path, tmp_path: Path, edit) -> Path:
    run = tmp_path / "edited"
    shutil.copytree(good_run, run)
    meta = json.loads((run / RUN_FILE).read_text())
    text = edit(meta)
    (run / RUN_FILE).write_text(text if isinstance(text, str) else json.dumps(meta, indent=2))
    return run


HANDLED = [
    ("not json", lambda m: "{ this is not json", "is not valid JSON"),
    ("older format", lambda m: m.update(format=0), "field 'format'"),
    ("another app", lambda m: m.update(app="other-app"), "field 'app'"),
    ("no config", lambda m: m.pop("config"), "'config'"),
    ("another rig name", lambda m: m["config"]["rig"].update(name="ur5"), "config.rig.name"),
    (
        "unknown strategy",
        lambda m: m["config"]["strategy"].update(name="zz"),
        "config.strategy.name",
    ),
]


@pytest.mark.parametrize("label, edit, message", HANDLED, ids=[h[0] for h in HANDLED])
def test_a_broken_run_json_gets_one_line_and_nothing_is_written(
    good_run, tmp_path, capsys, label, edit, message
):
    run = _edited(good_run, tmp_path, edit)
    before = _bytes_of(run)
    code, err = _run_cli(["explore", "--resume", str(run), "--no-progress"], capsys)
    assert code == 2 and message in err and len(err.splitlines()) == 1, (label, err)
    assert _bytes_of(run) == before


# Wrong types that got a traceback before ``ergo explore`` checked the run's config.
UNHANDLED = [
    ("seed not a number", lambda m: m["config"].update(seed="abc"), "config.seed"),
    ("episodes a string", lambda m: m["config"].update(episodes="ten"), "config.episodes"),
    ("unknown episode key", lambda m: m["config"]["episode"].update(rate=40), "config.episode"),
    ("rig missing", lambda m: m["config"].pop("rig"), "config.rig"),
]


@pytest.mark.parametrize("label, edit, field", UNHANDLED, ids=[u[0] for u in UNHANDLED])
def test_a_mistyped_run_json_gets_one_line_naming_the_field(
    good_run, tmp_path, capsys, label, edit, field
):
    run = _edited(good_run, tmp_path, edit)
    before = _bytes_of(run)
    try:
        code, err = _run_cli(["explore", "--resume", str(run), "--no-progress"], capsys)
    finally:
        assert _bytes_of(run) == before  # holds today too: the crash comes before any write
    assert code == 2 and field in err and len(err.splitlines()) == 1, (label, err)


def test_resuming_with_another_rig_is_refused(good_run, tmp_path, capsys):
    run = tmp_path / "copy"
    shutil.copytree(good_run, run)
    before = _bytes_of(run)
    code, err = _run_cli(["explore", "--resume", str(run), "--rig", "dynamixel"], capsys)
    assert code == 2 and "--rig dynamixel differs" in err and len(err.splitlines()) == 1
    assert _bytes_of(run) == before


# ---- CLI flags -------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "args, message",
    [
        (["explore", "--episodes", "ten"], "--episodes: invalid int value"),
        (["explore", "--rig", "ur5"], "--rig: invalid choice"),
        (["explore", "--resume", "no/such/run"], "--resume no/such/run: no such run folder"),
        (["explore", "--resume", "x", "--out", "y"], "not both"),
        (["explore", "--resume-or-new"], "needs --out"),
    ],
)
def test_bad_flags_get_one_line(tmp_path, capsys, monkeypatch, args, message):
    monkeypatch.chdir(tmp_path)
    code, err = _run_cli(args, capsys)
    assert code == 2 and message in err and len(err.splitlines()) == 1, err
    assert list(tmp_path.iterdir()) == []  # nothing made


@pytest.mark.parametrize(
    "args, field",
    [
        (["--seed", "-1"], "--seed must be"),
        (["--rig-option", "render_size=5"], "--rig-option render_size must be"),
        (["--rig-option", "render_sise=[64,64]"], "--rig-option render_sise is unknown"),
        (["--strategy", "rge-efr", "--strategy-option", "sigma=lots"], "--strategy-option sigma"),
        (["--strategy", "rpe", "--strategy-option", "bootstrap=5"], "--strategy-option bootstrap"),
    ],
)
def test_bad_values_of_a_new_run_get_one_line_and_no_folder(
    tmp_path, capsys, monkeypatch, args, field
):
    monkeypatch.chdir(tmp_path)
    try:
        code, err = _run_cli(["explore", "--episodes", "1", "--out", "r", *args], capsys)
    finally:
        made = list(tmp_path.iterdir())
    assert code == 2 and field in err and len(err.splitlines()) == 1, err
    assert made == []


# ---- calibration files ----------------------------------------------------------------------
@pytest.mark.parametrize(
    "text, message",
    [
        ("{ nope", "JSON"),
        ('{"schema": "something-else"}', "schema"),
        ("[]", ""),
    ],
)
def test_a_broken_calibration_file_gets_one_line_and_is_left_alone(tmp_path, text, message):
    from calibration.store import CalibrationError, load_file

    path = tmp_path / "joints.json"
    path.write_text(text)
    before = path.read_bytes()
    with pytest.raises(CalibrationError) as exc:
        load_file(path, kind="joints")
    assert message in str(exc.value) and "\n" not in str(exc.value)
    assert path.read_bytes() == before


def test_a_calibration_file_of_binary_garbage_gets_one_line(tmp_path, capsys, monkeypatch):
    from calibration.store import CalibrationError, load_file

    rig = tmp_path / "cal" / "r1"
    rig.mkdir(parents=True)
    garbage = bytes(range(0x80, 0x100)) * 3
    for kind in ("joints", "arena"):
        (rig / f"{kind}.json").write_bytes(garbage)
    with pytest.raises(CalibrationError, match="binary data at byte 0") as exc:
        load_file(rig / "joints.json", kind="joints")
    assert "\n" not in str(exc.value)
    monkeypatch.setenv("ERGO_CALIBRATION_DIR", str(tmp_path / "cal"))
    main(["calibrate", "show", "--rig-id", "r1"])
    out = capsys.readouterr()
    assert "Traceback" not in out.err
    assert "arena: INVALID" in out.out and "joints: INVALID" in out.out
    # explore refuses a damaged arena file even for a strategy that needs no ball (a missing
    # one only warns): nothing made, the file left alone
    monkeypatch.chdir(tmp_path)
    args = ["explore", "--rig", "dynamixel", "--rig-id", "r1", "--port", "/dev/ttyNOPE",
            "--episodes", "1", "--out", "run", "--no-progress"]  # fmt: skip
    code, err = _run_cli(args, capsys)
    assert code == 2 and "binary data" in err and len(err.splitlines()) == 1, err
    assert not (tmp_path / "run").exists()
    assert (rig / "arena.json").read_bytes() == garbage


def test_a_missing_port_is_named_before_the_camera_and_leaves_no_run(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("ERGO_CALIBRATION_DIR", str(tmp_path / "cal"))
    args = ["explore", "--rig", "dynamixel", "--rig-id", "r1", "--port", "/dev/ttyNOPE",
            "--episodes", "1", "--out", "run", "--no-progress", "--rerun", "save"]  # fmt: skip
    for _ in range(2):  # the same command, again: nothing left blocks it
        code, err = _run_cli(args, capsys)
        assert code == 2 and "/dev/ttyNOPE: no such port" in err, err
        assert "camera" not in err and len(err.splitlines()) == 1, err
        assert not (tmp_path / "run").exists()


def test_a_second_run_on_a_busy_port_with_a_url_camera_is_refused_in_one_line(tmp_path):
    """Was: `FATAL: exception not rethrown`, rc 134 (the camera's stream thread was running
    when the busy port ended the process); the arm now connects before the camera."""
    import os
    import subprocess
    import sys

    import serial

    from sim.dynamixel.emulator import DynamixelEmulator
    from sim.dynamixel.server import PtyBusServer
    from sim.mjpeg_server import MjpegServer, TwinFrames
    from sim.twin import Twin

    twin = Twin(render_size=(64, 64))
    try:
        with (
            PtyBusServer(DynamixelEmulator(twin)) as server,
            MjpegServer(TwinFrames(twin), fps=10) as camera,
            serial.Serial(server.path, exclusive=True),  # the first run holds the port
        ):
            cmd = [sys.executable, "-m", "explore.cli", "explore", "--rig", "dynamixel",
                   "--rig-id", "r1", "--port", server.path, "--camera", camera.url,
                   "--episodes", "1", "--out", str(tmp_path / "run"), "--no-progress",
                   "--rerun", "off"]  # fmt: skip
            env = {**os.environ, "ERGO_CALIBRATION_DIR": str(tmp_path / "cal")}
            done = subprocess.run(cmd, capture_output=True, text=True, timeout=120, env=env)
    finally:
        twin.close()
    last = done.stderr.strip().splitlines()[-1]
    assert done.returncode == 2, done.stderr
    assert "port busy" in last and server.path in last, done.stderr
    assert not (tmp_path / "run").exists()


def test_report_on_a_run_json_with_a_null_seed_gets_one_line(good_run, tmp_path, capsys):
    run = _edited(good_run, tmp_path, lambda m: m["config"].update(seed=None))
    before = _bytes_of(run)
    code, err = _run_cli(["report", str(run)], capsys)
    assert code == 2 and "config.seed" in err and len(err.splitlines()) == 1, err
    assert _bytes_of(run) == before


def test_out_under_a_regular_file_gets_one_line(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "afile").write_text("mine")
    code, err = _run_cli(["explore", "--episodes", "1", "--out", "afile/run"], capsys)
    assert code == 2 and "afile is a file" in err and len(err.splitlines()) == 1, err
    assert (tmp_path / "afile").read_text() == "mine"


@pytest.mark.parametrize(
    ("change", "field"),
    [
        ({"homography": [[1.0, 2.0, 3.0], [2.0, 4.0, 6.0], [0.0, 0.0, 1.0]]}, "homography"),
        ({"homography": [[1e300, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]}, "homography"),
        ({"dist_coeffs": [1e300, 0.0, 0.0, 0.0, 0.0]}, "dist_coeffs"),
        ({"camera_matrix": [[1e300, 0.0, 320.0], [0.0, 600.0, 240.0], [0.0, 0.0, 1.0]]},
         "camera_matrix"),
    ],
)  # fmt: skip
def test_an_arena_file_out_of_all_scale_is_refused(tmp_path, change, field):
    """Finite but absurd numbers (issue 29): a singular homography maps no plane, 1e300
    overflows every pixel mapped through it; both were accepted."""
    from calibration.store import CalibrationError, validate

    arena = {
        "camera_matrix": [[600.0, 0.0, 320.0], [0.0, 600.0, 240.0], [0.0, 0.0, 1.0]],
        "dist_coeffs": [0.1, -0.05, 0.0, 0.0, 0.0],
        "image_size": [640, 480],
        "homography": [[1e-3, 0.0, -0.3], [0.0, 1e-3, -0.2], [0.0, 0.0, 1.0]],
        "centre": [0.0, 0.0],
        "radius": 0.2,
    }
    validate("arena", arena)  # the sound file passes
    with pytest.raises(CalibrationError) as info:
        validate("arena", {**arena, **change})
    assert field in str(info.value) and "\n" not in str(info.value)
