"""The ball tracker: HSV thresholds, morphology, the largest plausible blob, its position in
pixels and on the arena, and its polar coordinates around the arena centre.

It never reports a silently wrong position: when the ball is hidden (by the arm), cut by the
image border, outside the arena, or when two ball-coloured blobs make it ambiguous, the result
has ``seen=False`` and a ``reason`` in words.

The default colour range is the original rig's (flowersteam/APEX ``poppimage``, see
docs/facts.md): OpenCV HSV [27, 45, 70] - [38, 255, 255], hue 0..179.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from vision.ball_outline import OutlineFit, fit_outline
from vision.rectify import ArenaModel, arena_to_pixels, pixels_to_arena, polar

# Original rig's ball range (the original implementation). Hue 0..179, saturation and value 0..255.
BALL_HSV_LOWER = (27, 45, 70)
BALL_HSV_UPPER = (38, 255, 255)
# Ball radius used when an arena model is given, metres: the twin's ball (sim/models/
# make_scene.py BALL_RADIUS; vision imports no other package, so a test checks the two agree);
# the real rig's foam ball is of that size (a guess there).
BALL_RADIUS_M = 0.03


@dataclass(frozen=True)
class HSVRange:
    """One inclusive OpenCV HSV box: hue 0..179, saturation and value 0..255.

    Red straddles hue 0/179 and needs two ranges, e.g. (0..8) and (172..179).
    """

    lower: tuple[int, int, int]
    upper: tuple[int, int, int]

    def __post_init__(self) -> None:
        lo = tuple(int(v) for v in self.lower)
        hi = tuple(int(v) for v in self.upper)
        if len(lo) != 3 or len(hi) != 3:
            raise ValueError(f"HSV bounds need 3 values each, got {self.lower}, {self.upper}")
        for name, bound in (("lower", lo), ("upper", hi)):
            if not (0 <= bound[0] <= 179 and 0 <= bound[1] <= 255 and 0 <= bound[2] <= 255):
                raise ValueError(f"HSV {name} bound {bound} outside H 0..179, S, V 0..255")
        if any(a > b for a, b in zip(lo, hi, strict=True)):
            raise ValueError(f"HSV lower {lo} exceeds upper {hi} (for red use two ranges)")
        object.__setattr__(self, "lower", lo)
        object.__setattr__(self, "upper", hi)

    def to_list(self) -> list[list[int]]:
        return [list(self.lower), list(self.upper)]

    @classmethod
    def from_list(cls, value: Any) -> HSVRange:
        lo, hi = value
        return cls(tuple(lo), tuple(hi))

    @classmethod
    def parse(cls, text: str) -> HSVRange:
        """``"27,45,70:38,255,255"`` (lower:upper) -> ``HSVRange``; ``ValueError`` if not."""
        try:
            lo, hi = text.split(":")
            return cls(tuple(int(v) for v in lo.split(",")), tuple(int(v) for v in hi.split(",")))
        except ValueError as exc:
            raise ValueError(f"bad HSV range {text!r} ({exc}): expected H,S,V:H,S,V") from None


@dataclass(frozen=True)
class TrackerConfig:
    """Tracker settings. Gate values are guesses tuned on the twin's renders (see
    docs/vision.md), not measurements of the real rig.

    Attributes:
        ranges: HSV ranges whose union is "ball-coloured".
        open_px: side of the square opening kernel (removes speckle), pixels; 0: none.
        close_px: side of the closing kernel (fills highlights and noise holes), pixels; 0: none.
        min_area_px, max_area_px: blob area gates, pixels. None: derived from the expected
            ball radius when an arena model is given (0.35x to 2.5x its disc), else 12 and 1/8
            of the image.
        min_circularity: area / area of the minimum enclosing circle. On twin renders a whole
            ball scores 0.90-0.95 (lens distortion and noise included), a ball with a sixth
            hidden under a link about 0.79 (its centroid then 4 mm off), half hidden about 0.4.
        ambiguity_ratio: another ball-coloured blob at least this fraction of the chosen
            blob's area makes the detection ambiguous.
        ball_radius_m: radius of the ball, metres: its centre is this high above the floor.
        arena_margin_m: how far beyond the arena radius a ball centre may be and still count.
        outline_fit: a blob that fails ``min_circularity`` is still the ball when its outline
            follows a circle of the ball's expected size there (``vision.ball_outline``):
            within ``outline_radius_tolerance`` of it, going round at least
            ``outline_min_arc_deg``, the blob filling at least ``outline_min_fill`` of the
            circle and no more than ``outline_max_outside`` of its area outside it; its centre
            is then the circle's. Needs an arena model with the camera's position (the
            expected size); without one, such a blob is refused as before. A ball against the
            arena's wall comes through a JPEG stream with a spur or a flattened side where
            its edge blends with the wall's (circularity 0.79-0.81 measured, docs/vision.md).
    """

    ranges: tuple[HSVRange, ...] = (HSVRange(BALL_HSV_LOWER, BALL_HSV_UPPER),)
    open_px: int = 3
    close_px: int = 5
    min_area_px: float | None = None
    max_area_px: float | None = None
    min_circularity: float = 0.85
    ambiguity_ratio: float = 0.25
    ball_radius_m: float = BALL_RADIUS_M
    arena_margin_m: float = 0.02
    outline_fit: bool = True
    # The gates' figures: experiments/tracker_wall.py on served stand-ins (docs/vision.md).
    # A ball's outline circle is within 0.98-1.05 of the expected radius: the circle is taken
    # for a ball within +-10 % (chosen with a margin); the fits that went wrong on an arm over
    # the ball were 0.75-0.86 of it (measured).
    outline_radius_tolerance: float = 0.10
    # Most of the ball is there (a quarter hidden at most; chosen): whole balls fill 0.93-0.99
    # of their circle; a chord hiding the 120 degrees the arc gate leaves hides 20 %.
    outline_min_fill: float = 0.75
    # A second ball-coloured thing joined to the ball (another ball, a patch) lies outside its
    # circle; a spur from a wall's edge covers under 0.01 of it (measured). Chosen.
    outline_max_outside: float = 0.05
    # The circle's centre is pinned from every side by 240 degrees of outline (chosen).
    outline_min_arc_deg: float = 240.0

    def __post_init__(self) -> None:
        ranges = tuple(r if isinstance(r, HSVRange) else HSVRange.from_list(r) for r in self.ranges)
        if not ranges:
            raise ValueError("the tracker needs at least one HSV range")
        object.__setattr__(self, "ranges", ranges)

    def to_dict(self) -> dict[str, Any]:
        return {
            "ranges": [r.to_list() for r in self.ranges],
            "open_px": self.open_px,
            "close_px": self.close_px,
            "min_area_px": self.min_area_px,
            "max_area_px": self.max_area_px,
            "min_circularity": self.min_circularity,
            "ambiguity_ratio": self.ambiguity_ratio,
            "ball_radius_m": self.ball_radius_m,
            "arena_margin_m": self.arena_margin_m,
            "outline_fit": self.outline_fit,
            "outline_radius_tolerance": self.outline_radius_tolerance,
            "outline_min_fill": self.outline_min_fill,
            "outline_max_outside": self.outline_max_outside,
            "outline_min_arc_deg": self.outline_min_arc_deg,
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> TrackerConfig:
        kw = dict(d)
        kw["ranges"] = tuple(HSVRange.from_list(r) for r in kw.get("ranges", []))
        return cls(**kw)


@dataclass(frozen=True)
class Blob:
    """One connected ball-coloured region.

    Attributes:
        centroid: (u, v) pixel centroid of the region's pixels, raw pixels.
        area: pixel count.
        radius: radius of the minimum enclosing circle, pixels.
        circularity: area / (pi radius^2).
        touches_border: whether the region reaches the image's edge.
        outline: the region's boundary points, (n, 2) raw pixels (``findContours``).
        pixels: the region in its bounding box, (h, w) bool.
        origin: (u, v) of that box's top-left pixel.
    """

    centroid: tuple[float, float]
    area: float
    radius: float
    circularity: float
    touches_border: bool
    outline: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)), repr=False, compare=False)
    pixels: np.ndarray = field(
        default_factory=lambda: np.zeros((0, 0), bool), repr=False, compare=False
    )
    origin: tuple[int, int] = (0, 0)


@dataclass(frozen=True)
class BallObservation:
    """What the tracker saw in one frame.

    Attributes:
        seen: True only when exactly one plausible ball was found (and, with an arena model,
            it lies inside the arena).
        reason: "" when seen; otherwise why not, in words.
        pixel: (u, v) of the ball's centre in raw pixels, or None.
        radius_px: apparent radius, pixels, or None.
        xy: (x, y) of the ball's centre on the arena, metres, or None (also None without an
            arena model).
        r: distance to the arena centre, metres, or None.
        theta: angle around the arena centre, radians in (-pi, pi], or None.
        blobs: every ball-coloured blob considered, largest first (for debugging).
        outline: the circle fitted to the ball's outline when that, not the whole blob, gave
            its centre (``TrackerConfig.outline_fit``), else None.
    """

    seen: bool
    reason: str = ""
    pixel: tuple[float, float] | None = None
    radius_px: float | None = None
    xy: tuple[float, float] | None = None
    r: float | None = None
    theta: float | None = None
    blobs: tuple[Blob, ...] = field(default=(), repr=False)
    outline: OutlineFit | None = field(default=None, repr=False)

    @property
    def polar_features(self) -> np.ndarray | None:
        """(r, cos theta, sin theta): the wrap-safe polar form, shape (3,), or None."""
        if self.r is None or self.theta is None:
            return None
        return np.array([self.r, math.cos(self.theta), math.sin(self.theta)])

    def describe(self) -> str:
        """One line for logs and the ``ergo track`` command."""
        if not self.seen:
            return f"not seen: {self.reason}"
        u, v = self.pixel
        text = f"seen at pixel ({u:.1f}, {v:.1f}) radius {self.radius_px:.1f} px"
        if self.outline is not None:
            text += f" (outline fit, {self.outline.arc_deg:.0f} deg of it)"
        if self.xy is not None:
            text += (
                f"; arena ({self.xy[0] * 1000:+.1f}, {self.xy[1] * 1000:+.1f}) mm, "
                f"r {self.r * 1000:.1f} mm, theta {math.degrees(self.theta):+.1f} deg"
            )
        return text


class BallTracker:
    """Finds the ball in raw camera frames.

    Args:
        config: thresholds and gates.
        arena: the arena calibration; without it positions are in pixels only.
    """

    def __init__(self, config: TrackerConfig | None = None, arena: ArenaModel | None = None):
        self.config = config or TrackerConfig()
        self.arena = arena
        self._expected_radius_px: float | None = None
        if arena is not None and arena.camera_position is not None:
            self._expected_radius_px = self._expected_radius(arena)

    def _expected_radius(self, arena: ArenaModel) -> float:
        """Apparent ball radius at the arena centre, pixels (pinhole, near the optical axis)."""
        rad = self.config.ball_radius_m
        centre_px = arena_to_pixels(arena, arena.centre, height=rad)[0]
        edge_px = arena_to_pixels(arena, arena.centre + np.array((rad, 0.0)), height=rad)[0]
        return float(np.linalg.norm(edge_px - centre_px))

    def expected_radius_at(self, pixel: tuple[float, float]) -> float | None:
        """The ball's apparent radius where it is seen at ``pixel`` (u, v), pixels: its
        centre's place on the arena, one radius up, and four points a radius from it on that
        plane, through the lens (perspective and distortion); None without an arena model that
        knows the camera's position."""
        arena = self.arena
        if arena is None or arena.camera_position is None:
            return None
        rad = self.config.ball_radius_m
        xy = pixels_to_arena(arena, np.asarray(pixel, np.float64), height=rad)[0]
        ring = xy + rad * np.array([(1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0)])
        px = arena_to_pixels(arena, np.vstack([xy, ring]), height=rad)
        return float(np.linalg.norm(px[1:] - px[0], axis=1).mean())

    def area_gates(self, image_shape: tuple[int, ...]) -> tuple[float, float]:
        """(min, max) blob area in pixels for frames of this shape (H, W[, C])."""
        cfg = self.config
        lo, hi = cfg.min_area_px, cfg.max_area_px
        if self._expected_radius_px is not None:
            disc = math.pi * self._expected_radius_px**2
            # 0.35x: a ball more than about 2/3 hidden is not trusted; 2.5x: perspective at the
            # frame's edge grows the disc by well under that. Guesses.
            lo = 0.35 * disc if lo is None else lo
            hi = 2.5 * disc if hi is None else hi
        h, w = image_shape[:2]
        lo = 12.0 if lo is None else lo  # guess: below this a blob is noise
        hi = h * w / 8.0 if hi is None else hi  # guess: the ball never fills 1/8 of the frame
        return float(lo), float(hi)

    # ---- pixels ----------------------------------------------------------------------------
    def mask(self, image: np.ndarray) -> np.ndarray:
        """Ball-coloured pixels after morphology, shape (H, W), uint8 0/255.

        Args:
            image: BGR frame, shape (H, W, 3), uint8.
        """
        import cv2

        if image.ndim != 3 or image.shape[2] != 3:
            raise ValueError(f"expected a BGR image (H, W, 3), got shape {image.shape}")
        hsv = cv2.cvtColor(image, cv2.COLOR_BGR2HSV)
        mask = np.zeros(image.shape[:2], np.uint8)
        for rng in self.config.ranges:
            mask |= cv2.inRange(hsv, np.array(rng.lower), np.array(rng.upper))
        if self.config.open_px > 1:
            k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (self.config.open_px,) * 2)
            mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, k)
        if self.config.close_px > 1:
            k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (self.config.close_px,) * 2)
            mask = cv2.morphologyEx(mask, cv2.MORPH_CLOSE, k)
        return mask

    def blobs(self, mask: np.ndarray, min_area: float = 4.0) -> list[Blob]:
        """Connected regions of a mask with at least ``min_area`` pixels, largest first."""
        import cv2

        n, labels, stats, centroids = cv2.connectedComponentsWithStats(mask, connectivity=8)
        h, w = mask.shape
        out = []
        for i in range(1, n):
            area = float(stats[i, cv2.CC_STAT_AREA])
            if area < min_area:
                continue
            x, y = stats[i, cv2.CC_STAT_LEFT], stats[i, cv2.CC_STAT_TOP]
            bw, bh = stats[i, cv2.CC_STAT_WIDTH], stats[i, cv2.CC_STAT_HEIGHT]
            sub = (labels[y : y + bh, x : x + bw] == i).astype(np.uint8)
            contours, _ = cv2.findContours(sub, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
            pts = np.concatenate(contours).reshape(-1, 2).astype(np.float32)
            _, radius = cv2.minEnclosingCircle(pts)
            radius = max(float(radius), 0.5)
            # The enclosing circle passes through pixel centres: add half a pixel so that a
            # rasterised disc scores about 1 rather than more.
            circularity = area / (math.pi * (radius + 0.5) ** 2)
            touches = x == 0 or y == 0 or x + bw >= w or y + bh >= h
            cu, cv_ = centroids[i]
            out.append(
                Blob(
                    (float(cu), float(cv_)),
                    area,
                    radius + 0.5,
                    circularity,
                    touches,
                    pts + np.array([x, y], np.float32),
                    sub.astype(bool),
                    (int(x), int(y)),
                )
            )
        out.sort(key=lambda b: b.area, reverse=True)
        return out

    # ---- the decision ----------------------------------------------------------------------
    def track(self, image: np.ndarray) -> BallObservation:
        """Find the ball in one BGR frame (H, W, 3) uint8."""
        cfg = self.config
        lo, hi = self.area_gates(image.shape)
        blobs = self.blobs(self.mask(image))
        significant = [b for b in blobs if b.area >= 0.25 * lo]
        if not significant:
            return BallObservation(False, "no ball-coloured blob", blobs=tuple(blobs))
        outlines: dict[int, OutlineFit | None] = {}  # by blob index: the outline's circle
        plausible = []
        for i, b in enumerate(significant):
            if not lo <= b.area <= hi:
                continue
            if b.circularity >= cfg.min_circularity:
                plausible.append(b)
            elif cfg.outline_fit:
                outlines[i] = self.outline(b)
                if self.outline_refusal(b, outlines[i]) is None:
                    plausible.append(b)
        if not plausible:
            b = significant[0]
            if b.area > hi:
                why = f"largest ball-coloured blob too large ({b.area:.0f} px > {hi:.0f})"
            elif b.area < lo:
                why = f"ball-coloured blob too small ({b.area:.0f} px < {lo:.0f}): hidden?"
            else:
                why = (
                    f"ball-coloured blob not round (circularity {b.circularity:.2f} < "
                    f"{cfg.min_circularity:.2f}"
                )
                if 0 in outlines:
                    why += f"; {self.outline_refusal(b, outlines[0])}"
                why += "): partly hidden?"
            return BallObservation(False, why, blobs=tuple(blobs))
        best = plausible[0]
        fit = outlines.get(significant.index(best))
        rivals = [
            b for b in significant if b is not best and b.area >= cfg.ambiguity_ratio * best.area
        ]
        if rivals:
            return BallObservation(
                False,
                f"ambiguous: {len(rivals) + 1} ball-coloured blobs "
                f"(areas {best.area:.0f} and {rivals[0].area:.0f} px)",
                blobs=tuple(blobs),
            )
        if best.touches_border:
            return BallObservation(
                False, "ball at the image border (partly out of view)", blobs=tuple(blobs)
            )
        if fit is None:
            obs = BallObservation(
                True, "", pixel=best.centroid, radius_px=best.radius, blobs=tuple(blobs)
            )
        else:
            obs = BallObservation(
                True, "", pixel=fit.centre, radius_px=fit.radius, blobs=tuple(blobs), outline=fit
            )
        if self.arena is None:
            return obs
        return self._on_arena(obs)

    def outline(self, blob: Blob) -> OutlineFit | None:
        """The circle ``blob``'s outline follows (``vision.ball_outline.fit_outline``), or None
        without an expected radius (no arena model with the camera's position) or circle."""
        expected = self.expected_radius_at(blob.centroid)
        if expected is None or len(blob.outline) < 3:
            return None
        return fit_outline(blob.outline, blob.pixels, blob.origin, blob.centroid, expected)

    def outline_refusal(self, blob: Blob, fit: OutlineFit | None) -> str | None:
        """Why ``fit`` (of ``blob``'s outline) does not make the blob a ball, in words; None
        when it does (``TrackerConfig``'s ``outline_*`` gates)."""
        cfg = self.config
        if fit is None:
            if self.arena is None or self.arena.camera_position is None:
                return "no outline fit without an arena model"
            return "its outline follows no circle"
        expected = self.expected_radius_at(fit.centre)
        assert expected is not None
        ratio = fit.radius / expected
        if abs(ratio - 1.0) > cfg.outline_radius_tolerance:
            return f"its outline's circle is {ratio:.2f} of the ball's size"
        if fit.arc_deg < cfg.outline_min_arc_deg:
            return f"its outline goes {fit.arc_deg:.0f} deg round a circle"
        if fit.fill < cfg.outline_min_fill:
            return f"it fills {fit.fill:.2f} of its outline's circle"
        if fit.outside > cfg.outline_max_outside:
            return f"{fit.outside:.2f} of it lies outside its outline's circle"
        return None

    def _on_arena(self, obs: BallObservation) -> BallObservation:
        arena = self.arena
        assert arena is not None and obs.pixel is not None
        height = self.config.ball_radius_m if arena.camera_position is not None else 0.0
        xy = pixels_to_arena(arena, np.array(obs.pixel), height=height)[0]
        r, theta = polar(xy, arena.centre)
        limit = arena.radius + self.config.arena_margin_m
        if r > limit:
            return replace(
                obs,
                seen=False,
                reason=f"outside the arena (r {r * 1000:.0f} mm > {limit * 1000:.0f} mm)",
            )
        return replace(obs, xy=(float(xy[0]), float(xy[1])), r=float(r), theta=float(theta))


def tracker_config_from_arena(
    data: dict[str, Any], base: TrackerConfig | None = None
) -> TrackerConfig:
    """``base`` (default ``TrackerConfig()``) with the ball colour ranges and radius an arena
    calibration's ``data`` holds, where it holds them. The file's format belongs to
    ``calibration.store``; only this object is read here (``vision`` imports no other
    package). Its arena is ``ArenaModel.from_dict(data)``."""
    config = base if base is not None else TrackerConfig()
    if data.get("ball_hsv_ranges"):
        ranges = tuple(HSVRange.from_list(r) for r in data["ball_hsv_ranges"])
        config = replace(config, ranges=ranges)
    if data.get("ball_radius_m"):
        config = replace(config, ball_radius_m=float(data["ball_radius_m"]))
    return config
