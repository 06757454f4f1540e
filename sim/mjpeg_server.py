"""Serve camera frames as an MJPEG stream over HTTP on 127.0.0.1 only.

``GET /stream.mjpg`` answers ``multipart/x-mixed-replace`` with one JPEG part per frame, which
``cv2.VideoCapture("http://127.0.0.1:PORT/stream.mjpg")`` opens like a network camera;
``GET /snapshot.jpg`` answers the latest frame. One producer thread calls ``grab()`` (e.g.
``twin.render``) at ``fps`` and encodes it once; every client gets the same encoded frames.
Rendering stays in that one thread, so its OpenGL context is never shared.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import TYPE_CHECKING

import cv2
import numpy as np

from sim.loopback import HOST, LISTEN_BACKLOG

if TYPE_CHECKING:
    from sim.twin import Twin

log = logging.getLogger(__name__)

BOUNDARY = "ergoframe"
# Frame rate and JPEG quality: guesses that keep a 240x240 render cheap on a shared core.
DEFAULT_FPS = 15.0
DEFAULT_JPEG_QUALITY = 85


class TwinFrames:
    """Renders a camera of a twin with a renderer of its own, for one producer thread.

    An EGL context is bound to the thread that made it current, so sharing ``Twin.render``'s
    renderers between threads fails; this one is created, used and closed by the thread that
    calls it (``MjpegServer`` closes it from its producer thread). The twin's lock is held only
    while the scene is copied, not while it is rendered.

    Args:
        twin: the twin.
        camera: camera name in the model.
        size: (height, width), pixels (default: the twin's ``render_size``).
    """

    def __init__(self, twin: Twin, camera: str = "overhead", size: tuple[int, int] | None = None):
        self.twin = twin
        self.camera = camera
        self.size = size or twin.render_size
        self._renderer = None

    def __call__(self) -> np.ndarray:
        """The current view, shape (H, W, 3), BGR uint8."""
        import mujoco

        if self._renderer is None:
            self._renderer = mujoco.Renderer(self.twin.model, *self.size)
        with self.twin.lock:
            self._renderer.update_scene(self.twin.data, camera=self.camera)
        rgb = self._renderer.render()
        return np.ascontiguousarray(rgb[:, :, ::-1])

    def close(self) -> None:
        """Free the renderer (from the thread that rendered)."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None


class _Server(ThreadingHTTPServer):
    request_queue_size = LISTEN_BACKLOG  # socketserver's 5 dropped connections (sim.loopback)


class MjpegServer:
    """An MJPEG stream of ``grab()`` frames.

    Args:
        grab: returns a BGR image, shape (H, W, 3), uint8. Called from the producer thread
            only; if it has a ``close()`` method, that thread calls it when it stops (e.g.
            ``TwinFrames``).
        port: TCP port on 127.0.0.1 (0: any free port; see ``port`` after ``start``).
        fps: frames per second produced.
        jpeg_quality: 0..100.
    """

    def __init__(
        self,
        grab: Callable[[], np.ndarray],
        port: int = 0,
        fps: float = DEFAULT_FPS,
        jpeg_quality: int = DEFAULT_JPEG_QUALITY,
    ) -> None:
        if fps <= 0:
            raise ValueError(f"fps must be positive, got {fps}")
        self.grab = grab
        self.fps = fps
        self.jpeg_quality = jpeg_quality
        self._requested_port = port
        self._frame: bytes | None = None
        self._seq = 0
        self._cond = threading.Condition()
        self._stop = threading.Event()
        self._httpd: _Server | None = None
        self._threads: list[threading.Thread] = []

    @property
    def port(self) -> int:
        if self._httpd is None:
            raise RuntimeError("MJPEG server not started")
        return int(self._httpd.server_address[1])

    @property
    def url(self) -> str:
        """The stream's URL, for ``cv2.VideoCapture``."""
        return f"http://{HOST}:{self.port}/stream.mjpg"

    def start(self) -> None:
        if self._httpd is not None:
            return
        try:
            self._httpd = _Server((HOST, self._requested_port), self._handler_class())
        except OSError as exc:
            raise OSError(f"cannot serve MJPEG on {HOST}:{self._requested_port}: {exc}") from exc
        self._httpd.daemon_threads = True
        self._stop.clear()
        self._threads = [
            threading.Thread(target=self._produce, name="mjpeg-producer", daemon=True),
            threading.Thread(
                target=self._httpd.serve_forever, kwargs={"poll_interval": 0.1}, daemon=True
            ),
        ]
        for t in self._threads:
            t.start()

    def stop(self) -> None:
        self._stop.set()
        with self._cond:
            self._cond.notify_all()
        if self._httpd is not None:
            self._httpd.shutdown()
            self._httpd.server_close()
            self._httpd = None
        for t in self._threads:
            t.join(timeout=2.0)
        self._threads = []

    def __enter__(self) -> MjpegServer:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # ---- producer ----------------------------------------------------------------------------
    def _produce(self) -> None:
        try:
            self._produce_frames()
        finally:
            close = getattr(self.grab, "close", None)
            if callable(close):
                try:
                    close()
                except Exception as exc:
                    log.error("MJPEG source did not close: %s", exc)

    def _produce_frames(self) -> None:
        period = 1.0 / self.fps
        deadline = time.monotonic()
        params = [cv2.IMWRITE_JPEG_QUALITY, int(self.jpeg_quality)]
        while not self._stop.is_set():
            try:
                ok, jpeg = cv2.imencode(".jpg", self.grab(), params)
            except Exception as exc:  # keep serving the last frame; say why once per frame
                log.error("MJPEG frame failed: %s", exc)
                ok = False
            if ok:
                with self._cond:
                    self._frame = jpeg.tobytes()
                    self._seq += 1
                    self._cond.notify_all()
            deadline += period
            delay = deadline - time.monotonic()
            if delay < -period:
                deadline = time.monotonic()
            self._stop.wait(max(0.0, delay))

    def wait_frame(self, after: int = 0, timeout: float = 2.0) -> tuple[int, bytes | None]:
        """Block until a frame newer than sequence number ``after`` (0: any frame), at most
        ``timeout`` s; returns (seq, JPEG bytes or None)."""
        with self._cond:
            self._cond.wait_for(lambda: self._seq > after or self._stop.is_set(), timeout=timeout)
            return self._seq, self._frame

    # ---- HTTP --------------------------------------------------------------------------------
    def _handler_class(self) -> type[BaseHTTPRequestHandler]:
        server = self

        class Handler(BaseHTTPRequestHandler):
            def log_message(self, fmt: str, *args: object) -> None:
                log.debug("mjpeg: " + fmt, *args)

            def do_GET(self) -> None:
                path = self.path.split("?")[0]
                if path == "/stream.mjpg":
                    self._stream()
                elif path == "/snapshot.jpg":
                    _, frame = server.wait_frame(0)
                    if frame is None:
                        self.send_error(HTTPStatus.SERVICE_UNAVAILABLE, "no frame yet")
                        return
                    self.send_response(HTTPStatus.OK)
                    self.send_header("Content-Type", "image/jpeg")
                    self.send_header("Content-Length", str(len(frame)))
                    self.end_headers()
                    self.wfile.write(frame)
                else:
                    self.send_error(HTTPStatus.NOT_FOUND, "try /stream.mjpg or /snapshot.jpg")

            def _stream(self) -> None:
                self.send_response(HTTPStatus.OK)
                self.send_header("Cache-Control", "no-cache, private")
                self.send_header("Pragma", "no-cache")
                self.send_header("Content-Type", f"multipart/x-mixed-replace; boundary={BOUNDARY}")
                self.end_headers()
                seq = 0
                try:
                    while not server._stop.is_set():
                        seq, frame = server.wait_frame(seq)
                        if frame is None:
                            continue
                        self.wfile.write(
                            f"--{BOUNDARY}\r\nContent-Type: image/jpeg\r\n"
                            f"Content-Length: {len(frame)}\r\n\r\n".encode()
                        )
                        self.wfile.write(frame)
                        self.wfile.write(b"\r\n")
                        self.wfile.flush()
                except (BrokenPipeError, ConnectionResetError):
                    pass  # the client went away

        return Handler
