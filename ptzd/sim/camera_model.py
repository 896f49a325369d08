"""The simulator's exact camera model: a rotating pinhole view of a wide pinhole image.

The contract (also in ../shared/interfaces.md; checks outside the project rely on it):

- The wide frame (W x H) is a pinhole image with horizontal FOV `wide_hfov`, square pixels,
  principal point at the centre. World axes are the wide camera's: x right, y down, z forward.
- K(w, h, f) = [[F, 0, w/2], [0, F, h/2], [0, 0, 1]], F = (w/2) / tan(f/2).
- The view (w x h) with pan p (+ right), tilt t (+ up) and horizontal FOV f looks along
  R = R_pan(p) R_tilt(t); view pixel (u, v) shows the wide pixel
  K(W, H, wide_hfov) R K(w, h, f)^-1 (u, v, 1), sampled bilinearly, black outside the wide frame.

Rendering is one `cv2.warpPerspective(..., INTER_LINEAR | WARP_INVERSE_MAP)`. The only addition
is for poses that turn part of the view more than 90 degrees away from the wide camera's axis:
those rays point behind the wide camera, a homography would fold them back onto the image, so
that half-plane of the view is painted black (it is outside the wide frame by definition).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import cast

import cv2
import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
Image = npt.NDArray[np.uint8]
Box = tuple[float, float, float, float]  # x, y, w, h in pixels

# Rays closer than this to the plane z = 0 of a camera are treated as not in front of it: keeps
# projected coordinates finite (1e-9 rad off the plane is ~1e9 focal lengths off-centre).
_MIN_DEPTH = 1e-9


@dataclass(frozen=True, slots=True)
class Pose:
    """Where the view looks: pan (+ right) and tilt (+ up) in degrees, horizontal FOV in degrees."""

    pan: float
    tilt: float
    hfov: float


def focal_length(width: int, hfov_deg: float) -> float:
    """F = (w/2) / tan(f/2): focal length in pixels of a `width`-wide image with FOV `hfov_deg`."""
    if not 0.0 < hfov_deg < 180.0:
        raise ValueError(f"horizontal FOV must be in (0, 180) degrees, got {hfov_deg!r}")
    return (width / 2.0) / math.tan(math.radians(hfov_deg) / 2.0)


def intrinsics(width: int, height: int, hfov_deg: float) -> FloatArray:
    """K(w, h, f) = [[F, 0, w/2], [0, F, h/2], [0, 0, 1]]."""
    F = focal_length(width, hfov_deg)
    return np.array([[F, 0.0, width / 2.0], [0.0, F, height / 2.0], [0.0, 0.0, 1.0]])


def rotation_pan(pan_deg: float) -> FloatArray:
    """R_pan(p) = [[cos p, 0, sin p], [0, 1, 0], [-sin p, 0, cos p]]."""
    c, s = math.cos(math.radians(pan_deg)), math.sin(math.radians(pan_deg))
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rotation_tilt(tilt_deg: float) -> FloatArray:
    """R_tilt(t) = [[1, 0, 0], [0, cos t, -sin t], [0, sin t, cos t]]."""
    c, s = math.cos(math.radians(tilt_deg)), math.sin(math.radians(tilt_deg))
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rotation(pan_deg: float, tilt_deg: float) -> FloatArray:
    """R = R_pan(p) R_tilt(t): maps view-camera rays to wide-camera rays."""
    return rotation_pan(pan_deg) @ rotation_tilt(tilt_deg)


@dataclass(frozen=True, slots=True)
class PoseGeometry:
    """Everything derived from one pose, computed once (see `CameraModel.geometry`)."""

    view_to_wide: FloatArray  # H = K_wide R K_view^-1 (view pixel -> wide pixel)
    wide_to_view: FloatArray  # H^-1
    # view pixels (u, v) with  behind_u*u + behind_v*v + behind_c <= 0  look behind the wide camera
    behind: tuple[float, float, float]
    # corners (in view pixels) of the part of the view looking behind the wide camera, or None
    behind_polygon: npt.NDArray[np.int32] | None


@dataclass(frozen=True, slots=True)
class PreparedWide:
    """A wide frame in the layout the warp is fastest on (see `CameraModel.prepare`)."""

    pixels: Image
    channels: int  # channels of the frame it was made from, and of the rendered view


class CameraModel:
    """The fixed part of the model: wide image size and FOV, view size.

    Pose-dependent matrices are cached (`geometry`), so rendering a stream of frames at a
    pose that changes only when the dome moves costs one warp per frame.
    """

    def __init__(
        self, wide_size: tuple[int, int], wide_hfov: float, view_size: tuple[int, int]
    ) -> None:
        for name, (w, h) in (("wide_size", wide_size), ("view_size", view_size)):
            if w < 1 or h < 1:
                raise ValueError(f"{name} must be positive, got {w}x{h}")
        self.wide_size = (int(wide_size[0]), int(wide_size[1]))
        self.view_size = (int(view_size[0]), int(view_size[1]))
        self.wide_hfov = float(wide_hfov)
        self.K_wide = intrinsics(*self.wide_size, self.wide_hfov)
        self.K_wide_inv = np.linalg.inv(self.K_wide)
        self._scratch_in: Image | None = None
        self._scratch_out: dict[int, Image] = {}
        # a per-instance cache: a pose's geometry is pure in (pan, tilt, hfov)
        self.geometry = lru_cache(maxsize=64)(self._geometry)

    def K_view(self, hfov: float) -> FloatArray:  # noqa: N802 - the papers' K
        return intrinsics(*self.view_size, hfov)

    def _geometry(self, pose: Pose) -> PoseGeometry:
        R = rotation(pose.pan, pose.tilt)
        K_view = self.K_view(pose.hfov)
        K_view_inv = np.linalg.inv(K_view)
        H = self.K_wide @ R @ K_view_inv
        H_inv = K_view @ R.T @ self.K_wide_inv
        # depth (z in the wide camera) of the ray through view pixel (u, v) is linear in (u, v)
        depth = R[2] @ K_view_inv
        behind = (float(depth[0]), float(depth[1]), float(depth[2]))
        polygon = self._behind_polygon(behind)
        H.setflags(write=False)
        H_inv.setflags(write=False)
        return PoseGeometry(H, H_inv, behind, polygon)

    def _behind_polygon(self, plane: tuple[float, float, float]) -> npt.NDArray[np.int32] | None:
        """The view rectangle clipped to `a*u + b*v + c <= _MIN_DEPTH`, grown by a pixel."""
        a, b, c = plane
        w, h = self.view_size
        # one pixel outside the view on every side so boundary pixels are covered by fillPoly
        corners = [(-1.0, -1.0), (w + 1.0, -1.0), (w + 1.0, h + 1.0), (-1.0, h + 1.0)]
        # include pixels within ~1.5 px of the boundary (depth changes by `hypot(a, b)` a pixel)
        margin = 1.5 * math.hypot(a, b)

        def value(p: tuple[float, float]) -> float:
            return a * p[0] + b * p[1] + c - _MIN_DEPTH - margin

        inside = [value(p) <= 0.0 for p in corners]
        if not any(inside):
            return None
        out: list[tuple[float, float]] = []
        for i, p in enumerate(corners):
            q = corners[(i + 1) % 4]
            vp, vq = value(p), value(q)
            if vp <= 0.0:
                out.append(p)
            if (vp <= 0.0) != (vq <= 0.0):
                s = vp / (vp - vq)
                out.append((p[0] + s * (q[0] - p[0]), p[1] + s * (q[1] - p[1])))
        return np.round(np.array(out)).astype(np.int32)

    # --- rendering -----------------------------------------------------------------------

    def prepare(self, wide: Image, *, scratch: bool = False) -> PreparedWide:
        """Check a wide frame and convert it once for any number of renders.

        BGR frames are warped as BGRA: OpenCV's vectorised bilinear path for 4 channels is
        about 2.5x faster than for 3, and the output is bit-identical (channels are
        interpolated independently; the test suite checks it). With `scratch`, the BGRA
        copy goes to a buffer the model reuses (valid until the next call).
        """
        height, width = wide.shape[:2]
        if (width, height) != self.wide_size:
            raise ValueError(
                f"wide frame is {width}x{height}, the model expects "
                f"{self.wide_size[0]}x{self.wide_size[1]}"
            )
        if wide.dtype != np.uint8:
            raise ValueError(f"wide frame must be uint8, got {wide.dtype}")
        if wide.ndim == 3 and wide.shape[2] == 3:
            if not scratch:
                return PreparedWide(cast(Image, cv2.cvtColor(wide, cv2.COLOR_BGR2BGRA)), 3)
            if self._scratch_in is None:
                self._scratch_in = np.empty((height, width, 4), np.uint8)
            cv2.cvtColor(wide, cv2.COLOR_BGR2BGRA, dst=self._scratch_in)
            return PreparedWide(self._scratch_in, 3)
        if wide.ndim == 2 or wide.shape[2] in (1, 4):
            return PreparedWide(wide, 1 if wide.ndim == 2 else wide.shape[2])
        raise ValueError(f"wide frame must have 1, 3 or 4 channels, got shape {wide.shape}")

    def render(self, wide: Image | PreparedWide, pose: Pose) -> Image:
        """The view at `pose` of a wide frame (grey, BGR or BGRA uint8, or `prepare`d).

        The result has the wide frame's channels and is a new array. Large intermediate
        buffers are reused between calls (allocating megabytes per frame costs more than the
        warp here), so one model must not render from two threads at once.
        """
        prepared = wide if isinstance(wide, PreparedWide) else self.prepare(wide, scratch=True)
        geo = self.geometry(pose)
        pixels = prepared.pixels
        channels = 1 if pixels.ndim == 2 else pixels.shape[2]
        warp_into = self._scratch_out.get(channels) if prepared.channels == 3 else None
        view = cast(
            Image,
            cv2.warpPerspective(
                pixels,
                geo.view_to_wide,
                self.view_size,
                dst=warp_into,
                flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                borderMode=cv2.BORDER_CONSTANT,
                borderValue=0,
            ),
        )
        if geo.behind_polygon is not None:
            cv2.fillPoly(view, [geo.behind_polygon], 0)
        if prepared.channels == 3:
            self._scratch_out[channels] = view
            return cast(Image, cv2.cvtColor(view, cv2.COLOR_BGRA2BGR))
        if prepared.channels == 1 and view.ndim == 3:
            return view[:, :, 0].copy()
        return view

    # --- points --------------------------------------------------------------------------

    def view_to_wide(self, points: npt.ArrayLike, pose: Pose) -> FloatArray:
        """Wide pixels shown at view pixels `points` (N x 2); NaN rows look behind the wide one."""
        return _apply(self.geometry(pose).view_to_wide, points)

    def wide_to_view(self, points: npt.ArrayLike, pose: Pose) -> FloatArray:
        """View pixels where wide pixels `points` (N x 2) appear; NaN rows are behind the view."""
        return _apply(self.geometry(pose).wide_to_view, points)

    # --- boxes ---------------------------------------------------------------------------

    def box_to_view(self, box: Box, pose: Pose) -> Box | None:
        """Bounding box in the view of wide box `box` (x, y, w, h), clipped; None if not visible.

        A homography maps the box's edges to straight lines, so the bounding box of the
        projected outline is exact; the part of the outline behind the view is cut off first.
        """
        x, y, w, h = box
        corners = np.array([[x, y, 1.0], [x + w, y, 1.0], [x + w, y + h, 1.0], [x, y + h, 1.0]])
        rays = corners @ self.geometry(pose).wide_to_view.T  # homogeneous view coordinates
        if np.all(rays[:, 2] > _MIN_DEPTH):
            projected = rays[:, :2] / rays[:, 2:3]
        else:
            clipped = _clip_polygon_to_depth(rays)
            if clipped is None:
                return None
            projected = clipped[:, :2] / clipped[:, 2:3]
        vw, vh = self.view_size
        x0 = max(0.0, float(projected[:, 0].min()))
        y0 = max(0.0, float(projected[:, 1].min()))
        x1 = min(float(vw), float(projected[:, 0].max()))
        y1 = min(float(vh), float(projected[:, 1].max()))
        if x1 <= x0 or y1 <= y0:
            return None
        return (x0, y0, x1 - x0, y1 - y0)


def _apply(H: FloatArray, points: npt.ArrayLike) -> FloatArray:
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    homog = pts @ H[:, :2].T + H[:, 2]
    depth = homog[:, 2:3]
    with np.errstate(divide="ignore", invalid="ignore"):
        out = homog[:, :2] / depth
    out[depth[:, 0] <= _MIN_DEPTH] = np.nan
    return out


def _clip_polygon_to_depth(rays: FloatArray) -> FloatArray | None:
    """Sutherland-Hodgman clip of a closed polygon of homogeneous points to z >= depth."""
    limit = 1e-6
    out: list[FloatArray] = []
    n = len(rays)
    for i in range(n):
        p, q = rays[i], rays[(i + 1) % n]
        if p[2] >= limit:
            out.append(p)
        if (p[2] >= limit) != (q[2] >= limit):
            s = (limit - p[2]) / (q[2] - p[2])
            out.append(p + s * (q - p))
    if len(out) < 3:
        return None
    return np.array(out)
