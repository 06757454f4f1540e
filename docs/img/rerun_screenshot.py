"""Screenshot of the rerun viewer showing recordings with their default blueprint (for the docs).

Runs the viewer that ``ergo replay RUN`` opens (this environment's ``rerun``, the same file
arguments), but headless (``--headless``: an offscreen window, no display needed; it still needs
a Vulkan or GL adapter, e.g. Mesa's software lavapipe from Debian's ``mesa-vulkan-drivers``),
listening on 127.0.0.1 only. Through the viewer's control API (``rerun.experimental.
ViewerClient``, rerun 0.41) it waits until the files are loaded, puts the time cursor at the
end of the ``time`` timeline (paused), lets the views fetch their data and paint, and saves a
screenshot (PNG, 1600 x 1000 px; ``--width`` scales it down, ``--colors N`` reduces it to an
N-colour palette; a median-cut palette loses the few pixels of small coloured points).

Usage: python docs/img/rerun_screenshot.py --out docs/img/rerun_view.png RUN/recording.rrd ...
       python docs/img/rerun_screenshot.py --out docs/img/rerun_lerobot.png DATASET \
           --timeline frame_index --recording episode_3      # an exported LeRobot dataset

Any path the viewer opens will do: a LeRobot dataset folder is read by rerun's own LeRobot
loader, one recording per episode (``--recording`` picks the one shown).
"""

from __future__ import annotations

import argparse
import io
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

VIEWER_SIZE = "1600x1000"  # logical points (1 px each at scale 1)


def connect_loaded(url: str, timeout_s: float, recording: str | None = None) -> Any:
    """Connect to the viewer at ``url`` once it answers, then wait until a recording with
    timelines (``recording``: that one) is open and nothing is loading; returns the
    ``ViewerClient``."""
    from rerun.experimental import ViewerClient

    deadline = time.monotonic() + timeout_s
    client, last = None, None
    while time.monotonic() < deadline:
        try:
            client = client or ViewerClient(url)
            state = client.get_state()
            ready = [r for r in state.recordings if r.timelines]
            if recording is not None:
                ready = [r for r in ready if recording in str(r)]
            if ready and not state.loading:
                return client
        except ConnectionError as exc:  # the viewer is still starting: no server yet
            last = exc
        time.sleep(0.5)
    raise TimeoutError(f"the viewer did not load the recording in {timeout_s} s ({last})")


def screenshot(
    files: list[Path],
    out: Path,
    width: int,
    settle_s: float,
    port: int,
    timeout_s: float,
    colors: int = 0,
    timeline: str = "time",
    recording: str | None = None,
) -> Path:
    """Open ``files`` in a headless viewer and save its screenshot to ``out`` (PNG)."""
    from PIL import Image

    exe = Path(sys.executable).parent / "rerun"
    cmd = [
        str(exe), "--headless", "--bind", "127.0.0.1", "--port", str(port),
        "--window-size", VIEWER_SIZE, "--hide-welcome-screen",
        *(str(f.resolve()) for f in files),
    ]  # fmt: skip
    env = dict(os.environ)
    env.setdefault("XDG_RUNTIME_DIR", tempfile.mkdtemp(prefix="rerun-xdg-"))
    log_path = out.with_suffix(".viewer.log")
    with open(log_path, "w") as log_file:
        viewer = subprocess.Popen(cmd, env=env, stdout=log_file, stderr=subprocess.STDOUT)
    try:
        client = connect_loaded(f"rerun+http://127.0.0.1:{port}/proxy", timeout_s, recording)
        state = client.get_state()
        shown = state.recordings[0]
        if recording is not None:
            shown = next(r for r in state.recordings if recording in str(r))
            client.set_location(shown.location)
        timelines = {t.name: t for t in shown.timelines}
        end = timelines[timeline].end
        if timeline == "time":  # a duration timeline, ns
            client.set_time(timeline, duration=end / 1e9, play_state="paused")
        else:  # a sequence (frame_index of a LeRobot dataset)
            client.set_time(timeline, sequence=int(end), play_state="paused")
        time.sleep(settle_s)  # the views fetch their chunks and repaint
        png = client.take_screenshot()
        for view in client.get_state().views:
            for report in view.reports:
                print(f"view {view.name!r}: {report.severity}: {report.summary}", file=sys.stderr)
    finally:
        viewer.terminate()
        try:
            viewer.wait(10)
        except subprocess.TimeoutExpired:
            viewer.kill()
    image = Image.open(io.BytesIO(png)).convert("RGB")
    if image.width > width:
        image = image.resize((width, round(image.height * width / image.width)), Image.LANCZOS)
    if colors:
        image = image.quantize(
            colors=colors, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE
        )
    out.parent.mkdir(parents=True, exist_ok=True)
    image.save(out, optimize=True)
    log_path.unlink(missing_ok=True)
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument(
        "files", nargs="+", type=Path, help=".rrd recordings (one run's files) or a dataset"
    )
    p.add_argument("--out", type=Path, required=True, help="PNG to write")
    p.add_argument("--width", type=int, default=1600, help="at most this wide, px")
    p.add_argument("--settle", type=float, default=15.0, help="s to let the views paint")
    p.add_argument("--port", type=int, default=9877, help="viewer port on 127.0.0.1")
    p.add_argument("--timeout", type=float, default=120.0, help="s to wait for the load")
    p.add_argument("--colors", type=int, default=0, help="palette size (0: full RGB)")
    p.add_argument("--timeline", default="time", help="timeline to put the cursor at the end of")
    p.add_argument("--recording", default=None, help="show the recording whose id has this")
    args = p.parse_args(argv)
    out = screenshot(
        args.files, args.out, args.width, args.settle, args.port, args.timeout, args.colors,
        args.timeline, args.recording,
    )  # fmt: skip
    print(f"{out}: {out.stat().st_size // 1024} kB")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
