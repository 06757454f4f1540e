"""``SimCamera``: the ``vision.Camera`` interface on the twin's overhead camera.

Besides the ideal pinhole render, the camera can imitate a real one:

- a known lens distortion (OpenCV's radial/tangential model ``k1 k2 p1 p2 k3``), applied by
  remapping the ideal render so that every output pixel shows what the distorted lens would
  see there; ``intrinsics()`` returns the camera matrix and the coefficients that a correct
  calibration must recover;
- Gaussian sensor noise of a given standard deviation (grey levels), from a seeded generator.

Pixel convention (OpenCV): pixel (u, v) = (column, row), the centre of the top-left pixel is
(0, 0). Measured on the twin: MuJoCo's render puts the optical axis at ((W-1)/2, (H-1)/2) in this
convention (the ball's silhouette centroid agrees with the projection to 0.1 px).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from sim.twin import Twin
from vision.camera import Camera, CameraError, Frame
from vision.observation import square_observation


def ideal_camera_matrix(fovy_deg: float, size: tuple[int, int]) -> np.ndarray:
    """Pinhole camera matrix of a MuJoCo camera, shape (3, 3), pixels.

    Args:
        fovy_deg: the camera's vertical field of view, degrees (MJCF ``fovy``).
        size: (height, width) of the image, pixels.

    MuJoCo renders square pixels: fx = fy = (H / 2) / tan(fovy / 2); the principal point is the
    image centre ((W - 1) / 2, (H - 1) / 2) in OpenCV's pixel-centre convention.
    """
    h, w = size
    f = (h / 2.0) / math.tan(math.radians(fovy_deg) / 2.0)
    return np.array([[f, 0.0, (w - 1) / 2.0], [0.0, f, (h - 1) / 2.0], [0.0, 0.0, 1.0]])


def distortion_maps(
    camera_matrix: np.ndarray,
    dist_coeffs: np.ndarray,
    size: tuple[int, int],
    ideal_matrix: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Remap tables that turn an ideal (pinhole) image into the distorted one.

    For every pixel of the distorted output, the ideal pixel that the lens maps there: the
    output pixel is undistorted (OpenCV's iterative inverse of the distortion model) and
    re-projected with the ideal image's camera matrix.

    Args:
        camera_matrix: of the distorted output, shape (3, 3), pixels.
        dist_coeffs: OpenCV coefficients ``(k1, k2, p1, p2[, k3])``, shape (4,) or (5,).
        size: (height, width) of the output, pixels.
        ideal_matrix: of the ideal image, shape (3, 3), pixels (default ``camera_matrix``: the
            same size and focal length; another lets a larger render with MuJoCo's centred,
            square pixels stand for any camera matrix, ``sim.standin.lens``).

    Returns:
        (map_x, map_y), each shape (H, W), float32: source column and row in the ideal image.
    """
    import cv2

    h, w = size
    u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    pts = np.stack([u.ravel(), v.ravel()], axis=1).reshape(-1, 1, 2)
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-10)
    dist = np.asarray(dist_coeffs, dtype=np.float64)
    target = camera_matrix if ideal_matrix is None else np.asarray(ideal_matrix, np.float64)
    ideal = cv2.undistortPoints(pts, camera_matrix, dist, None, None, target, criteria)
    ideal = ideal.reshape(h, w, 2)
    return ideal[..., 0].astype(np.float32), ideal[..., 1].astype(np.float32)


class SimCamera(Camera):
    """Renders the twin's named camera.

    Args:
        twin: the twin to render.
        camera: MJCF camera name.
        size: (height, width) in pixels (default: the twin's render size).
        dist_coeffs: lens distortion ``(k1, k2, p1, p2[, k3])`` (OpenCV model), or None for an
            ideal pinhole camera.
        noise_std: standard deviation of additive Gaussian sensor noise, grey levels (0..255
            scale); 0 for none.
        seed: seed of the noise generator (frames are reproducible for a given seed).
    """

    def __init__(
        self,
        twin: Twin,
        camera: str = "overhead",
        size: tuple[int, int] | None = None,
        dist_coeffs: np.ndarray | tuple[float, ...] | None = None,
        noise_std: float = 0.0,
        seed: int | None = 0,
    ):
        super().__init__()
        self.twin = twin
        self.camera = camera
        self.size = size or twin.render_size
        self.dist_coeffs = (
            None if dist_coeffs is None else np.asarray(dist_coeffs, dtype=np.float64).ravel()
        )
        if self.dist_coeffs is not None and self.dist_coeffs.size not in (4, 5, 8):
            raise ValueError(f"dist_coeffs needs 4, 5 or 8 values, got {self.dist_coeffs.size}")
        if noise_std < 0:
            raise ValueError(f"noise_std must be >= 0, got {noise_std}")
        self.noise_std = float(noise_std)
        self._rng = np.random.default_rng(seed)
        self._maps: tuple[np.ndarray, np.ndarray] | None = None

    # ---- the camera model ------------------------------------------------------------------
    @property
    def fovy(self) -> float:
        """Vertical field of view, degrees."""
        return float(self.twin.model.cam(self.camera).fovy[0])

    def intrinsics(self) -> tuple[np.ndarray, np.ndarray]:
        """(camera matrix (3, 3) in pixels, distortion coefficients (5,)) of the frames this
        camera delivers: what a camera calibration should recover."""
        k = ideal_camera_matrix(self.fovy, self.size)
        dist = np.zeros(5)
        if self.dist_coeffs is not None:
            dist[: min(5, self.dist_coeffs.size)] = self.dist_coeffs[:5]
        return k, dist

    def extrinsics(self) -> tuple[np.ndarray, np.ndarray]:
        """World-to-camera pose in OpenCV's camera frame (x right, y down, z forward).

        Returns:
            (R, t): rotation shape (3, 3) and translation shape (3,), metres, such that a world
            point X (m) is at ``R @ X + t`` in the camera frame.
        """
        with self.twin.lock:
            cam = self.twin.data.cam(self.camera)
            xmat = np.asarray(cam.xmat, dtype=float).reshape(3, 3)
            pos = np.asarray(cam.xpos, dtype=float).copy()
        # MuJoCo cameras look along their -z with y up; OpenCV's look along +z with y down.
        r_world_to_mj = xmat.T
        flip = np.diag([1.0, -1.0, -1.0])
        r = flip @ r_world_to_mj
        return r, -r @ pos

    def project(self, points: np.ndarray) -> np.ndarray:
        """Pixels of world points in the delivered (distorted) frames.

        Args:
            points: shape (N, 3), metres, world frame.

        Returns:
            shape (N, 2), pixels (u, v).
        """
        import cv2

        r, t = self.extrinsics()
        k, dist = self.intrinsics()
        rvec, _ = cv2.Rodrigues(r)
        px, _ = cv2.projectPoints(
            np.asarray(points, dtype=np.float64).reshape(-1, 1, 3), rvec, t, k, dist
        )
        return px.reshape(-1, 2)

    # ---- Camera interface ------------------------------------------------------------------
    def _connect(self) -> None:
        pass

    def _disconnect(self) -> None:
        pass

    def _read(self) -> Frame:
        return self._frame(self.twin.render(self.camera, self.size), distort=True)

    def read_square(self, side: int) -> Frame:
        """The centre square of the view rendered directly at (side, side): what
        ``vision.observation.square_observation`` makes of a full frame, at a fraction of its cost
        when nothing else needs the frame (the twin's outcome image). Exact for square and
        landscape frames (the square spans the vertical field of view). A distorted camera
        renders its full frame and crops it (its distortion is defined on that frame)."""
        if not self.is_connected:
            raise CameraError(f"{type(self).__name__} is not connected: call connect() first")
        if self.dist_coeffs is not None and np.any(self.dist_coeffs):
            frame = self._read()
            return Frame(square_observation(frame.image, side), frame.timestamp)
        return self._frame(self.twin.render(self.camera, (side, side)), distort=False)

    def _frame(self, image: np.ndarray, distort: bool) -> Frame:
        """A render with the camera's distortion (``distort``) and noise applied."""
        timestamp = self.twin.time
        if distort and self.dist_coeffs is not None and np.any(self.dist_coeffs):
            import cv2

            if self._maps is None:
                k, _ = self.intrinsics()
                self._maps = distortion_maps(k, self.dist_coeffs, self.size)
            image = cv2.remap(
                image, *self._maps, interpolation=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE
            )
        if self.noise_std > 0:
            noisy = image.astype(np.float32) + self._rng.normal(
                0.0, self.noise_std, image.shape
            ).astype(np.float32)
            image = np.clip(np.rint(noisy), 0, 255).astype(np.uint8)
        return Frame(image, timestamp)


def write_marker_scene(
    out_dir: str | Path,
    markers: dict[int, tuple[float, float]],
    marker_size: float,
    dictionary: int | None = None,
    scene: str | Path | None = None,
    texture_px: int = 2048,
    floor_rgb: tuple[float, float, float] | None = None,
) -> Path:
    """A copy of the twin's scene whose floor shows ArUco markers (for calibration tests).

    The floor keeps its colour (the twin's blue, or ``floor_rgb``); each marker is drawn with
    a white quiet zone of one cell into the floor's texture, which MuJoCo maps once over the
    whole floor plane.

    Args:
        out_dir: folder to write the scene, its included model files and the texture into.
        markers: marker id -> centre (x, y) in metres on the floor (world frame).
        marker_size: side of each marker's black square, metres.
        dictionary: ``cv2.aruco`` predefined dictionary id (default ``DICT_4X4_50``).
        scene: the scene to copy (default: the twin's ``scene.xml``).
        texture_px: side of the floor texture, pixels (2048 over 1 m: 0.5 mm per texel).
        floor_rgb: the floor's and the kerb's colour, (r, g, b) in 0..1
            (``sim.models.make_scene.scene_xml``); only with the twin's own scene.

    Returns:
        path of the new scene file, to pass as ``Twin(scene=...)``.

    Raises:
        ValueError: ``floor_rgb`` with another ``scene``, or not three numbers in 0..1.
    """
    import re
    import shutil

    import cv2

    from sim.twin import SCENE

    scene = Path(scene or SCENE)
    if floor_rgb is None:
        text = scene.read_text()
    elif scene == SCENE:
        from sim.models.make_scene import scene_xml

        text = scene_xml(floor_rgb=floor_rgb)
    else:
        raise ValueError("floor_rgb recolours the twin's own scene only")
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    for xml in scene.parent.glob("*.xml"):
        if xml != scene:
            shutil.copy(xml, out_dir / xml.name)
    match = re.search(r'<geom name="floor" type="plane" size="([\d.]+) ([\d.]+)', text)
    if match is None:
        raise ValueError(f"{scene} has no floor plane geom named 'floor'")
    half_x, half_y = float(match.group(1)), float(match.group(2))
    rgb = re.search(r'name="floor_tex"[^>]*rgb1="([\d.]+) ([\d.]+) ([\d.]+)"', text)
    floor_rgb = [float(c) for c in rgb.groups()] if rgb else [0.12, 0.22, 0.7]

    n = texture_px
    tex = np.zeros((n, n, 3), np.float32)
    tex[:] = [255.0 * c for c in reversed(floor_rgb)]  # BGR
    dico = cv2.aruco.getPredefinedDictionary(
        cv2.aruco.DICT_4X4_50 if dictionary is None else dictionary
    )
    for marker_id, (x, y) in markers.items():
        _draw_marker(tex, dico, int(marker_id), (x, y), marker_size, (half_x, half_y))
    tex_path = out_dir / "floor_markers.png"
    cv2.imwrite(str(tex_path), np.clip(np.rint(tex), 0, 255).astype(np.uint8))
    text = re.sub(
        r'<texture name="floor_tex"[^>]*/>',
        f'<texture name="floor_tex" type="2d" file="{tex_path.name}"/>',
        text,
    )
    text = text.replace(
        '<material name="floor_mat" texture="floor_tex"/>',
        '<material name="floor_mat" texture="floor_tex" texrepeat="1 1" texuniform="false"/>',
    )
    out = out_dir / scene.name
    out.write_text(text)
    return out


def _draw_marker(
    tex: np.ndarray,
    dico,
    marker_id: int,
    centre: tuple[float, float],
    size: float,
    half: tuple[float, float],
    supersample: int = 8,
) -> None:
    """Draw one marker (and a one-cell white quiet zone) into a floor texture, area-sampled.

    Texel (row, col) of an (n, n) texture covers x in [col, col + 1] * 2 hx / n - hx and, as
    MuJoCo maps a plane's texture (row 0 at +y, checked by detecting the rendered markers),
    y in hy - [row, row + 1] * 2 hy / n. Each texel averages ``supersample``^2 point samples, so
    the marker's edges land at their exact metric positions.
    """
    import cv2

    n = tex.shape[0]
    hx, hy = half
    cells = dico.markerSize + 2  # data bits plus the black border, per side
    bits = cv2.aruco.generateImageMarker(dico, marker_id, cells) > 127  # (cells, cells), white
    cell = size / cells
    quiet = cell  # white margin around the marker, metres
    x0, y0 = centre[0] - size / 2 - quiet, centre[1] + size / 2 + quiet  # top-left, metres
    c_lo = int(np.floor((x0 + hx) * n / (2 * hx)))
    c_hi = int(np.ceil((x0 + size + 2 * quiet + hx) * n / (2 * hx)))
    r_lo = int(np.floor((hy - y0) * n / (2 * hy)))
    r_hi = int(np.ceil((hy - y0 + size + 2 * quiet) * n / (2 * hy)))
    sub = (np.arange(supersample) + 0.5) / supersample
    cols = (np.arange(c_lo, c_hi)[:, None] + sub[None]).ravel()
    rows = (np.arange(r_lo, r_hi)[:, None] + sub[None]).ravel()
    xs = cols * 2 * hx / n - hx
    ys = hy - rows * 2 * hy / n
    # Marker-local coordinates from the top-left of the quiet zone, metres (down = -y).
    lx = xs[None, :] - x0
    ly = y0 - ys[:, None]
    inside_zone = (lx >= 0) & (lx < size + 2 * quiet) & (ly >= 0) & (ly < size + 2 * quiet)
    ci = np.floor((lx - quiet) / cell).astype(int)
    ri = np.floor((ly - quiet) / cell).astype(int)
    in_marker = (ci >= 0) & (ci < cells) & (ri >= 0) & (ri < cells)
    white = np.where(in_marker, bits[np.clip(ri, 0, cells - 1), np.clip(ci, 0, cells - 1)], True)
    patch_old = tex[r_lo:r_hi, c_lo:c_hi]
    hh, ww = r_hi - r_lo, c_hi - c_lo
    grey = np.where(white, 255.0, 0.0)
    # Samples outside the quiet zone keep the floor's colour: blend per sample.
    zone = inside_zone.reshape(hh, supersample, ww, supersample).mean(axis=(1, 3))
    value = (grey * inside_zone).reshape(hh, supersample, ww, supersample).mean(axis=(1, 3))
    tex[r_lo:r_hi, c_lo:c_hi] = patch_old * (1 - zone[..., None]) + value[..., None]
