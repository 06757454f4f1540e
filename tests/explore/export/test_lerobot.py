"""``ergo export lerobot``: the LeRobotDataset v3.0 layout, read back by readers no one here
wrote (rerun's built-in LeRobot loader, pyarrow, Hugging Face ``datasets``, pandas, PyAV), the
values against the runs' histories, and bad input refused in one line with nothing written."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from explore.cli import main
from explore.export.episodes import ExportError
from explore.export.lerobot import VIDEO_KEY, export_lerobot, run_names
from explore.runs.layout import HISTORY_FILE
from explore.runs.lock import run_lock
from explore.runs.store import read_frames, read_history

pa = pytest.importorskip("pyarrow")
pq = pytest.importorskip("pyarrow.parquet")
av = pytest.importorskip("av")

EPISODES = 6
SIDE = 64
RATE = 40


def _explore(out: Path, strategy: str, *options: str) -> Path:
    args = ["explore", "--rig", "sim", "--strategy", strategy, "--episodes", str(EPISODES),
            "--seed", "3", "--out", str(out), "--no-progress", "--rerun", "off",
            "--rig-option", "render_size=[64,64]"]  # fmt: skip
    for option in options:
        args += ["--rig-option", option]
    if strategy != "rpe":
        args += ["--strategy-option", "bootstrap=3"]
    assert main(args) == 0
    return out


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("runs")
    return {
        "goals": _explore(root / "goals", "rge-efr", f"record_video={SIDE}"),
        "random": _explore(root / "random", "rpe", f"record_video={SIDE}"),
        "no_video": _explore(root / "no_video", "rpe"),
    }


@pytest.fixture(scope="module")
def dataset(runs, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("export") / "ds"
    assert (
        main(["export", "lerobot", str(runs["goals"]), str(runs["random"]), "--out", str(out)]) == 0
    )
    return out


def test_the_docs_headless_snippet_reads_the_export(dataset, tmp_path):
    """docs/ecosystem.md's snippet, as written but for the dataset's path, run without a
    display; it reads the dataset the README's export command writes."""
    root = Path(__file__).parents[3]
    doc = (root / "docs" / "ecosystem.md").read_text()
    section = doc.split("### Reading it back without a display", 1)[1]
    snippet = section.split("```python\n", 1)[1].split("```", 1)[0]
    readme_out = re.search(r"ergo export lerobot \S+ --out (\S+)", (root / "README.md").read_text())
    assert readme_out, "the README's export command"
    named = f'Path("{readme_out.group(1)}")'
    assert named in snippet and f"--out {readme_out.group(1)}" in doc
    script = tmp_path / "read_back.py"
    script.write_text(snippet.replace(named, f"Path({str(dataset)!r})"))
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    done = subprocess.run(
        [sys.executable, str(script)], capture_output=True, text=True, timeout=120, env=env
    )
    assert done.returncode == 0, done.stderr
    frames = pq.read_table(dataset / "data/chunk-000/file-000.parquet").num_rows
    lines = done.stdout.splitlines()
    assert lines[0] == f"{2 * EPISODES} episodes, {frames} frames at {RATE} fps"
    assert lines[1].startswith("episode 0 (motor babbling, run goals): 40 frames, first action [")
    assert lines[2] == f"first video frame ({SIDE}, {SIDE}, 3)"


def _info(ds: Path) -> dict:
    return json.loads((ds / "meta/info.json").read_text())


def test_the_layout_is_lerobots_v3(dataset):
    for rel in ("meta/info.json", "meta/stats.json", "meta/tasks.parquet",
                "meta/episodes/chunk-000/file-000.parquet", "data/chunk-000/file-000.parquet",
                f"videos/{VIDEO_KEY}/chunk-000/file-000.mp4"):  # fmt: skip
        assert (dataset / rel).is_file(), rel
    info = _info(dataset)
    assert info["codebase_version"] == "v3.0" and info["fps"] == RATE
    assert info["total_episodes"] == 2 * EPISODES and info["total_frames"] == 2 * EPISODES * 40
    assert (
        info["data_path"].format(chunk_index=0, file_index=0) == "data/chunk-000/file-000.parquet"
    )
    feats = info["features"]
    names = ["m1.pos", "m2.pos", "m3.pos", "m4.pos", "m5.pos", "m6.pos"]
    assert feats["observation.state"]["names"] == feats["action"]["names"] == names
    assert feats["episode.dmp_parameters"]["shape"] == [48]
    assert feats[VIDEO_KEY]["shape"] == [SIDE, SIDE, 3]
    assert feats[VIDEO_KEY]["info"]["video.codec"] == "av1"
    stats = json.loads((dataset / "meta/stats.json").read_text())
    assert set(stats) == set(feats)
    assert stats["action"]["count"] == [info["total_frames"]]
    assert np.array(stats[VIDEO_KEY]["mean"]).shape == (3, 1, 1)


def test_the_parquet_files_have_the_declared_schema_for_pyarrow(dataset):
    feats = _info(dataset)["features"]
    table = pq.read_table(dataset / "data/chunk-000/file-000.parquet")
    declared = {k for k, f in feats.items() if f["dtype"] != "video"}
    assert set(table.schema.names) == declared
    for key in declared:
        f, t = feats[key], table.schema.field(key).type
        if f["shape"] == [1]:
            assert t == pa.from_numpy_dtype(np.dtype(f["dtype"])), key
        else:
            assert t == pa.list_(pa.from_numpy_dtype(np.dtype(f["dtype"])), f["shape"][0]), key
    assert table.column("index").to_pylist() == list(range(table.num_rows))


def test_hf_datasets_loads_the_frames_with_the_declared_features(dataset):
    datasets = pytest.importorskip("datasets")
    loaded = datasets.load_dataset(
        "parquet", data_files=str(dataset / "data/chunk-000/file-000.parquet"), split="train",
        cache_dir=str(dataset.parent / "hf-cache"),
    )  # fmt: skip
    expected = {}  # LeRobot's rule (lerobot/datasets/feature_utils.py) from info.json
    for key, f in _info(dataset)["features"].items():
        if f["dtype"] == "video":
            continue
        value = datasets.Value(f["dtype"])
        expected[key] = value if f["shape"] == [1] else datasets.List(value, length=f["shape"][0])
    assert loaded.features == datasets.Features(expected)
    assert len(loaded) == _info(dataset)["total_frames"]


def test_pandas_reads_the_tasks_as_lerobot_does(dataset):
    pd = pytest.importorskip("pandas")
    tasks = pd.read_parquet(dataset / "meta/tasks.parquet")
    assert tasks.index.name == "task"
    assert tasks.loc["motor babbling", "task_index"] == 0
    assert "goal in module 0" in tasks.index


def test_the_values_are_the_runs(dataset, runs):
    table = pq.read_table(dataset / "data/chunk-000/file-000.parquet").to_pydict()
    episodes = pq.read_table(dataset / "meta/episodes/chunk-000/file-000.parquet").to_pylist()
    records = read_history(runs["goals"]).records + read_history(runs["random"]).records
    assert len(episodes) == len(records)
    for e, (row, rec) in enumerate(zip(episodes, records, strict=True)):
        a, b = row["dataset_from_index"], row["dataset_to_index"]
        assert row["episode_index"] == e and b - a == len(rec.targets) == row["length"]
        state = np.array(table["observation.state"][a:b])
        np.testing.assert_allclose(np.array(table["action"][a:b]), rec.targets, atol=1e-6)
        np.testing.assert_allclose(state[1:], rec.measured[:-1], atol=1e-6)
        np.testing.assert_allclose(state[0], rec.start_positions, atol=1e-6)
        np.testing.assert_allclose(
            np.array(table["episode.dmp_parameters"][a]), rec.theta, atol=1e-6
        )
        assert table["frame_index"][a:b] == list(range(b - a))
        np.testing.assert_allclose(table["timestamp"][a:b], np.arange(b - a) / RATE, atol=1e-6)
        task = "motor babbling" if rec.kind == "random" else f"goal in module {rec.module}"
        assert row["tasks"] == [task]
        assert row["ergo/episode"] == rec.episode
        span = (row[f"videos/{VIDEO_KEY}/from_timestamp"], row[f"videos/{VIDEO_KEY}/to_timestamp"])
        assert span == pytest.approx((a / RATE, b / RATE))
    goals = [r for r in records if r.kind != "random"]
    assert goals, "the goal run set goals after its bootstrap"


def test_the_export_names_its_runs_and_holds_no_local_path(dataset, runs):
    episodes = pq.read_table(dataset / "meta/episodes/chunk-000/file-000.parquet").to_pylist()
    assert [row["ergo/run"] for row in episodes] == ["goals"] * EPISODES + ["random"] * EPISODES
    local = str(runs["goals"].resolve().parent)  # where the runs lie on this machine
    for path in dataset.rglob("*"):
        if path.suffix == ".parquet":
            table = pq.read_table(path)
            text = str(table.to_pylist()) + str(table.schema.metadata)
        elif path.is_file():
            text = path.read_bytes().decode("latin-1")  # json; the mp4's own metadata
        else:
            continue
        assert local not in text and str(Path.home()) not in text, path


def test_runs_are_named_from_the_folder_that_holds_them_all(tmp_path):
    camp = tmp_path / "campaign"
    assert run_names([camp / "rge-efr/seed-0", camp / "rpe/seed-0"]) == [
        "rge-efr/seed-0",
        "rpe/seed-0",
    ]
    assert run_names([Path("runs/A")]) == ["A"]


def test_the_video_frames_are_the_frames_the_runs_kept(dataset, runs):
    with av.open(str(dataset / f"videos/{VIDEO_KEY}/chunk-000/file-000.mp4")) as c:
        decoded = np.stack([f.to_ndarray(format="rgb24") for f in c.decode(video=0)])
    assert decoded.shape == (2 * EPISODES * 40, SIDE, SIDE, 3)
    kept = np.concatenate(
        [read_frames(r, k) for r in (runs["goals"], runs["random"]) for k in range(EPISODES)]
    )[..., ::-1]  # BGR -> RGB
    decoded = decoded.astype(float)
    aligned = np.abs(decoded - kept).mean(axis=(1, 2, 3))
    shifted = np.abs(decoded[1:] - kept[:-1]).mean(axis=(1, 2, 3))  # one tick late
    # AV1 at LeRobot's crf 30 is lossy (6 grey levels on average at 64 px, measured), and the
    # frames are where they belong: a tick late they differ more (the arm moved)
    assert aligned.mean() < 10.0, aligned.mean()
    assert aligned.mean() < shifted.mean() - 1.0, (aligned.mean(), shifted.mean())


def _rerun_log(dataset: Path, rrd: Path) -> None:
    code = (
        "import sys, rerun as rr; rr.init('ergo-export-test', spawn=False); rr.save(sys.argv[2]);"
        " rr.log_file_from_path(sys.argv[1])"
    )
    subprocess.run([sys.executable, "-c", code, str(dataset), str(rrd)], check=True, timeout=120)


def test_reruns_lerobot_loader_opens_the_dataset(dataset, tmp_path):
    rrc = pytest.importorskip("rerun.chunk")
    rrd = tmp_path / "ds.rrd"
    _rerun_log(dataset, rrd)
    reader = rrc.RrdReader(rrd)
    episodes = {
        s.recording_id: s for s in reader.recordings() if s.recording_id.startswith("episode_")
    }
    assert sorted(episodes) == sorted(f"episode_{k}" for k in range(2 * EPISODES))
    table = pq.read_table(dataset / "data/chunk-000/file-000.parquet").to_pydict()
    for k in (0, EPISODES + 1):  # one of each run
        chunks = list(reader.stream(store=episodes[f"episode_{k}"]).to_chunks())
        by_entity: dict[str, list] = {}
        for chunk in chunks:
            by_entity.setdefault(str(chunk.entity_path).lstrip("/"), []).append(chunk)
        for entity in ("observation.state", "action", "task", VIDEO_KEY, "episode.goal",
                       "episode.dmp_parameters"):  # fmt: skip
            assert entity in by_entity, (k, sorted(by_entity))
        rows = []
        for chunk in by_entity["observation.state"]:
            batch = chunk.to_record_batch()
            if "Scalars:scalars" in batch.schema.names:
                rows += batch.column("Scalars:scalars").to_pylist()
        a = k * 40
        np.testing.assert_allclose(rows, table["observation.state"][a : a + 40], atol=1e-6)
        texts = [
            t
            for c in by_entity["task"]
            for t in c.to_record_batch().column("TextDocument:text").to_pylist()
        ]
        # episode 0: the goal run's bootstrap; EPISODES + 1: the random run
        assert texts and all(t == ["motor babbling"] for t in texts)


# ---- bad input ------------------------------------------------------------------------------
def _one_line(args: list[str], capsys) -> str:
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    return err


def test_a_run_being_written_is_refused(runs, tmp_path, capsys):
    with run_lock(runs["goals"]):
        err = _one_line(
            ["export", "lerobot", str(runs["goals"]), "--out", str(tmp_path / "o")], capsys
        )
    assert "is being written" in err and not (tmp_path / "o").exists()
    assert f"pid {os.getpid()}" in err  # the holder named


def test_a_damaged_history_is_refused_and_left_as_it_was(runs, tmp_path, capsys):
    run = tmp_path / "damaged"
    shutil.copytree(runs["no_video"], run)
    data = bytearray((run / HISTORY_FILE).read_bytes())
    data[len(data) // 3] ^= 0xFF  # a bad record followed by good ones: corruption
    (run / HISTORY_FILE).write_bytes(bytes(data))
    err = _one_line(["export", "lerobot", str(run), "--out", str(tmp_path / "o")], capsys)
    assert "corrupt" in err or "record" in err
    assert (run / HISTORY_FILE).read_bytes() == bytes(data)
    assert not (tmp_path / "o").exists() and not any(tmp_path.glob(".o.partial*"))


def test_a_non_empty_out_is_refused_and_kept(runs, tmp_path, capsys):
    out = tmp_path / "o"
    out.mkdir()
    (out / "mine.txt").write_text("keep me")
    err = _one_line(["export", "lerobot", str(runs["no_video"]), "--out", str(out)], capsys)
    assert "not empty" in err and [p.name for p in out.iterdir()] == ["mine.txt"]


def test_runs_with_and_without_frames_need_no_video(runs, tmp_path, capsys):
    both = [str(runs["random"]), str(runs["no_video"])]
    err = _one_line(["export", "lerobot", *both, "--out", str(tmp_path / "o")], capsys)
    assert "record_video" in err and "--no-video" in err
    summary = export_lerobot([runs["random"], runs["no_video"]], tmp_path / "o", video=False)
    assert summary.video_side == 0 and summary.episodes == 2 * EPISODES
    info = _info(tmp_path / "o")
    assert VIDEO_KEY not in info["features"] and info["video_path"] is None


def test_an_export_failing_midway_leaves_nothing(runs, tmp_path):
    run = tmp_path / "other-side"
    shutil.copytree(runs["random"], run)
    small = np.zeros((40, SIDE // 2, SIDE // 2, 3), dtype=np.uint8)  # frames of another size
    np.savez_compressed(run / "frames/episode-000004.npz", frames=small)
    with pytest.raises(ExportError, match="px"):
        export_lerobot([run], tmp_path / "o")
    assert not (tmp_path / "o").exists() and not any(tmp_path.glob(".o.partial*"))


@pytest.mark.parametrize("damage", ["missing", "truncated", "garbage", "empty"])
def test_episodes_without_readable_frames_are_left_out_and_named(runs, tmp_path, damage, capsys):
    """One frames file missing or damaged: the other episodes export with their video and the
    line names the episode left out (before: the whole video dropped without a word, or a
    BadZipFile traceback). ``ergo runs check`` names it too."""
    run = tmp_path / "lost-frames"
    shutil.copytree(runs["random"], run)
    path = run / "frames/episode-000004.npz"
    if damage == "missing":
        path.unlink()
    else:
        data = path.read_bytes()
        path.write_bytes({"truncated": data[: len(data) // 2], "garbage": b"not an npz",
                          "empty": b""}[damage])  # fmt: skip
    out = tmp_path / "o"
    assert main(["export", "lerobot", str(run), "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert "episode 4 left out" in err and "episode-000004.npz" in err and err.count("\n") == 1
    info = _info(out)
    assert info["total_episodes"] == EPISODES - 1 and VIDEO_KEY in info["features"]
    assert main(["runs", "check", str(run)]) == 0
    said = capsys.readouterr().out
    assert f"frames: {EPISODES - 1} of {EPISODES} episode(s)" in said
    assert ("missing: episode(s) 4" if damage == "missing" else "unreadable") in said
    assert "1 episode(s) lack readable camera frames" in said


def test_an_rpe_run_is_described_in_rge_efrs_goal_space(runs, tmp_path):
    export_lerobot([runs["no_video"]], tmp_path / "o", video=False)
    feats = _info(tmp_path / "o")["features"]
    assert feats["episode.outcome"]["shape"] == [3]  # (r_n, cos t, sin t)
    table = pq.read_table(tmp_path / "o/data/chunk-000/file-000.parquet").to_pydict()
    assert np.isnan(np.array(table["episode.goal"], dtype=float)).all()  # no goals
    # their statistics are NaN numbers, as LeRobot stores them (lerobot-train reads every
    # feature's statistics as numbers: a null made it fail)
    stats = json.loads((tmp_path / "o/meta/stats.json").read_text())["episode.goal"]
    values = stats["mean"] + stats["std"] + stats["q50"]
    assert all(isinstance(x, float) and np.isnan(x) for x in values)
    outcome = np.array(table["episode.outcome"], dtype=float)
    np.testing.assert_allclose(outcome[:, 1] ** 2 + outcome[:, 2] ** 2, 1.0, atol=1e-5)


def test_kept_frames_leave_the_twins_history_unchanged(runs, tmp_path):
    plain = _explore(tmp_path / "plain", "rge-efr")
    a, b = read_history(plain).records, read_history(runs["goals"]).records
    assert all(x.equals(y) for x, y in zip(a, b, strict=True))
    frames = read_frames(runs["goals"], 2)
    assert frames.shape == (40, SIDE, SIDE, 3) and frames.dtype == np.uint8
    assert read_frames(plain, 2) is None


def test_record_video_takes_an_even_side(tmp_path, capsys):
    args = ["explore", "--episodes", "1", "--out", str(tmp_path / "r"), "--rig-option"]
    err = _one_line([*args, "record_video=63"], capsys)
    assert "record_video" in err and "even" in err and not (tmp_path / "r").exists()
    with pytest.raises(ExportError):
        export_lerobot([tmp_path / "missing"], tmp_path / "o")


def test_a_learned_goal_space_is_the_runs_own(tmp_path):
    torch = pytest.importorskip("torch")
    from vision.vae import Vae, VaeConfig, load_vae

    torch.manual_seed(0)
    vae = Vae(VaeConfig())
    vae.config.kl_per_latent = [float(v) for v in np.arange(10)[::-1]]
    model = vae.save(tmp_path / "vae")
    run = tmp_path / "mge-vae"
    assert main(["explore", "--strategy", "mge-vae", "--episodes", "8", "--seed", "1", "--out",
                 str(run), "--no-progress", "--rerun", "off", "--rig-option", "render_size=[64,64]",
                 "--strategy-option", f"vae={model}", "--strategy-option", "bootstrap=4",
                 "--strategy-option", "random_episodes=0"]) == 0  # fmt: skip
    export_lerobot([run], tmp_path / "o", video=False)
    table = pq.read_table(tmp_path / "o/data/chunk-000/file-000.parquet").to_pydict()
    per_episode = {
        k: np.array(table[k][::40], dtype=float) for k in table if k.startswith("episode.")
    }
    records = read_history(run).records
    latents = load_vae(model).encode_bgr(np.stack([r.image for r in records]))
    np.testing.assert_allclose(per_episode["episode.outcome"], latents, atol=1e-5)
    # the context of a latent space is the previous outcome (zeros before the first)
    np.testing.assert_allclose(per_episode["episode.context"][0], 0.0)
    np.testing.assert_allclose(per_episode["episode.context"][1:], latents[:-1], atol=1e-5)
    for rec, goal in zip(records, per_episode["episode.goal"], strict=True):
        if rec.kind == "random":
            assert np.isnan(goal).all()
        else:  # a goal in a module of two latents: NaN elsewhere
            assert np.isfinite(goal).sum() == 2 and np.allclose(goal[np.isfinite(goal)], rec.goal)
