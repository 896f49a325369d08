"""Grey-level features of the learned likelihoods, vectorised over many boxes at once.

Ko 2013 (seed 000): each box is split into 3 x 2 subblocks (3 rows, 2 columns); per
subblock an Epanechnikov-weighted local intensity distribution (LID, eqs. 1-4) and an
oriented centre-symmetric LBP histogram (OCS-LBP, eqs. 5-6: 8 orientations at 45 deg,
magnitudes above a threshold T summed per orientation, min-max normalised).

Sun 2015 (seed 004): an RGB 3x3x3 histogram and a uniform rotation-invariant LBP(8,1)
histogram (10 bins), 37 values per box.

Boxes are rows of (cx, cy, w, h) in frame pixels. Histograms with a kernel are gathered on
a fixed grid of normalised positions per box and accumulated with one `np.bincount` (as in
ptzd/vision/color.py); OCS-LBP sums come from an integral image (4 lookups per subblock).
"""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray

from ptzd.vision.likelihood import FloatArray

GreyImage = NDArray[np.uint8]
IntArray = NDArray[np.intp]

SUBBLOCK_ROWS, SUBBLOCK_COLS = 3, 2
SUBBLOCKS = SUBBLOCK_ROWS * SUBBLOCK_COLS
ORIENTATIONS = 8
# Neighbour k of the 8 at radius 1 lies at k * 45 deg counter-clockwise from east
# (image y grows downwards): (dy, dx).
NEIGHBOURS = ((0, 1), (-1, 1), (-1, 0), (-1, -1), (0, -1), (1, -1), (1, 0), (1, 1))


def to_grey(frame: NDArray[np.uint8]) -> GreyImage:
    """An 8-bit grey image from BGR (HxWx3), single-channel (HxW or HxWx1) input."""
    if frame.ndim == 2:
        return frame
    if frame.ndim == 3 and frame.shape[2] == 1:
        return frame[:, :, 0]
    if frame.ndim == 3 and frame.shape[2] == 3:
        return np.asarray(cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY), dtype=np.uint8)
    raise ValueError(f"frame must be HxW, HxWx1 or HxWx3, got shape {frame.shape}")


def to_bgr(frame: NDArray[np.uint8]) -> NDArray[np.uint8]:
    """A BGR image from BGR or single-channel input (grey replicated)."""
    if frame.ndim == 3 and frame.shape[2] == 3:
        return frame
    grey = to_grey(frame)
    return np.asarray(cv2.cvtColor(grey, cv2.COLOR_GRAY2BGR), dtype=np.uint8)


def _neighbour(padded: NDArray[np.uint8], k: int) -> NDArray[np.uint8]:
    dy, dx = NEIGHBOURS[k]
    h, w = padded.shape[0] - 2, padded.shape[1] - 2
    out: NDArray[np.uint8] = padded[1 + dy : 1 + dy + h, 1 + dx : 1 + dx + w]
    return out


def ocs_lbp_maps(grey: GreyImage, threshold: float) -> NDArray[np.uint8]:
    """Per-pixel OCS-LBP magnitudes, H x W x 8 (seed 000 eqs. 5-6).

    For each centre-symmetric pair (n_i, n_{i+4}), i = 0..3, the difference d = n_i - n_{i+4}
    goes, when |d| > T, as magnitude |d| into orientation bin i (d > 0) or i + 4 (d < 0).
    The border is replicated. Magnitudes are at most 255: uint8, which cv2.integral takes.
    """
    padded = np.asarray(cv2.copyMakeBorder(grey, 1, 1, 1, 1, cv2.BORDER_REPLICATE), np.uint8)
    half = ORIENTATIONS // 2
    # bin i takes d > 0 and bin i + 4 takes d < 0: saturating uint8 subtraction of the pair
    # one way or the other gives max(d, 0) or max(-d, 0); TOZERO keeps the values above T
    pairs = [(i, i + half) for i in range(half)] + [(i + half, i) for i in range(half)]
    channels = [
        cv2.threshold(
            cv2.subtract(_neighbour(padded, a), _neighbour(padded, b)),
            threshold,
            0,
            cv2.THRESH_TOZERO,
        )[1]
        for a, b in pairs
    ]
    return np.asarray(cv2.merge(channels), np.uint8).reshape(*grey.shape, ORIENTATIONS)


def min_max(h: FloatArray) -> FloatArray:
    """Min-max normalisation over the last axis; a flat histogram becomes all zeros."""
    lo = h.min(axis=-1, keepdims=True)
    span = h.max(axis=-1, keepdims=True) - lo
    out: FloatArray = np.where(span > 0, (h - lo) / np.where(span > 0, span, 1.0), 0.0)
    return out


def subblock_edges(boxes: FloatArray) -> tuple[IntArray, IntArray]:
    """Integer pixel edges of the 3x2 subblocks: x (N x 3) and y (N x 4), frame pixels."""
    x0 = boxes[:, 0] - boxes[:, 2] / 2
    y0 = boxes[:, 1] - boxes[:, 3] / 2
    fx = np.arange(SUBBLOCK_COLS + 1) / SUBBLOCK_COLS
    fy = np.arange(SUBBLOCK_ROWS + 1) / SUBBLOCK_ROWS
    xs = np.rint(x0[:, None] + boxes[:, 2:3] * fx[None, :]).astype(np.intp)
    ys = np.rint(y0[:, None] + boxes[:, 3:4] * fy[None, :]).astype(np.intp)
    return xs, ys


def epanechnikov_grid(samples: int) -> FloatArray:
    """Kernel weights k(||x||^2) = 1 - ||x||^2 of a samples x samples grid in one subblock.

    Sample centres sit at ((a + 0.5) / samples - 0.5) subblock sizes from the centre and are
    normalised by the radii h = (w/2, h/2) of the subblock (seed 000 eqs. 1-2), so the corners
    of the subblock lie at ||x||^2 = 2 (weight 0). Weights are not normalised here.
    """
    u = 2.0 * ((np.arange(samples) + 0.5) / samples - 0.5)
    r2 = u[None, :] ** 2 + u[:, None] ** 2
    weights: FloatArray = np.clip(1.0 - r2, 0.0, None)
    return weights


class FeatureMaps:
    """One frame's grey image and OCS-LBP integral image over a region, shared by all boxes."""

    def __init__(
        self,
        grey: GreyImage,
        region: tuple[int, int, int, int],
        lid_bins: int,
        ocs_threshold: float,
    ) -> None:
        x0, y0, x1, y1 = region
        self.origin = (x0, y0)
        self.grey = grey
        patch = grey[y0:y1, x0:x1]
        self.lid_bins = lid_bins
        # intensity bin of every pixel of the region, with a border of "outside" bins
        levels = (np.arange(256) * lid_bins // 256).astype(np.uint8)
        self._bins = cv2.copyMakeBorder(
            cv2.LUT(patch, levels), 1, 1, 1, 1, cv2.BORDER_CONSTANT, value=lid_bins
        )
        maps = ocs_lbp_maps(patch, ocs_threshold)
        # int32 holds 255 x 2^23 pixels; OpenCV's integral is ~18x numpy's double cumsum
        self._integral = np.asarray(cv2.integral(maps, sdepth=cv2.CV_32S), np.int32)

    def lid(self, boxes: FloatArray, samples: int) -> FloatArray:
        """Epanechnikov-weighted intensity histograms, N x 6 x lid_bins, each summing to 1.

        Samples outside the region count towards no bin but still towards the normaliser C,
        so a box half outside the frame has half a histogram.
        """
        n = boxes.shape[0]
        m = self.lid_bins
        cols, rows = SUBBLOCK_COLS * samples, SUBBLOCK_ROWS * samples
        u = (np.arange(cols) + 0.5) / cols - 0.5
        v = (np.arange(rows) + 0.5) / rows - 0.5
        h, w = self._bins.shape[0] - 2, self._bins.shape[1] - 2
        xs = np.floor(boxes[:, 0:1] - self.origin[0] + 1 + boxes[:, 2:3] * u[None, :])
        ys = np.floor(boxes[:, 1:2] - self.origin[1] + 1 + boxes[:, 3:4] * v[None, :])
        xi = np.clip(xs, 0, w + 1).astype(np.intp)
        yi = np.clip(ys, 0, h + 1).astype(np.intp) * (w + 2)
        sampled = self._bins.ravel().take(yi[:, :, None] + xi[:, None, :]).astype(np.intp)
        block = (np.arange(rows)[:, None] // samples) * SUBBLOCK_COLS + (
            np.arange(cols)[None, :] // samples
        )
        kernel = np.tile(epanechnikov_grid(samples), (SUBBLOCK_ROWS, SUBBLOCK_COLS))
        stride = SUBBLOCKS * (m + 1)
        index = (np.arange(n)[:, None, None] * stride) + block[None] * (m + 1) + sampled
        hist = np.bincount(
            index.ravel(), weights=np.tile(kernel.ravel(), n), minlength=n * stride
        ).reshape(n, SUBBLOCKS, m + 1)
        per_block = np.bincount(block.ravel(), weights=kernel.ravel(), minlength=SUBBLOCKS)
        out: FloatArray = hist[..., :m] / per_block[None, :, None]
        return out

    def ocs_lbp(self, boxes: FloatArray) -> FloatArray:
        """Min-max normalised OCS-LBP orientation histograms, N x 6 x 8."""
        xs, ys = subblock_edges(boxes)
        h, w = self._integral.shape[0] - 1, self._integral.shape[1] - 1
        xs = np.clip(xs - self.origin[0], 0, w)
        ys = np.clip(ys - self.origin[1], 0, h)
        ii = self._integral
        r = np.arange(SUBBLOCK_ROWS)
        c = np.arange(SUBBLOCK_COLS)
        ya, yb = ys[:, r][:, :, None], ys[:, r + 1][:, :, None]  # N x 3 x 1
        xa, xb = xs[:, c][:, None, :], xs[:, c + 1][:, None, :]  # N x 1 x 2
        sums = ii[yb, xb] - ii[ya, xb] - ii[yb, xa] + ii[ya, xa]  # N x 3 x 2 x 8
        return min_max(sums.reshape(boxes.shape[0], SUBBLOCKS, ORIENTATIONS).astype(np.float64))

    def variance(self, box: FloatArray) -> float:
        """Intensity variance of the frame inside `box` (0..255 levels)."""
        height, width = self.grey.shape
        x0 = int(np.clip(np.floor(box[0] - box[2] / 2), 0, width - 1))
        y0 = int(np.clip(np.floor(box[1] - box[3] / 2), 0, height - 1))
        x1 = int(np.clip(np.ceil(box[0] + box[2] / 2), x0 + 1, width))
        y1 = int(np.clip(np.ceil(box[1] + box[3] / 2), y0 + 1, height))
        return float(self.grey[y0:y1, x0:x1].var())


def region_of(boxes: FloatArray, shape: tuple[int, ...]) -> tuple[int, int, int, int]:
    """The frame region (x0, y0, x1, y1) covering all `boxes`, clipped to the frame."""
    height, width = shape[0], shape[1]
    half = boxes[:, 2:] / 2
    lo = np.floor((boxes[:, :2] - half).min(axis=0))
    hi = np.ceil((boxes[:, :2] + half).max(axis=0))
    x0 = min(max(int(lo[0]), 0), width - 1)
    y0 = min(max(int(lo[1]), 0), height - 1)
    x1 = min(max(int(hi[0]) + 1, x0 + 1), width)
    y1 = min(max(int(hi[1]) + 1, y0 + 1), height)
    return x0, y0, x1, y1


# -- Sun 2015: RGB 3x3x3 + uniform rotation-invariant LBP(8,1) --------------------------

RGB_BINS = 27
LBP_BINS = 10


def lbp_riu2(grey: GreyImage) -> NDArray[np.uint8]:
    """Uniform rotation-invariant LBP(8,1) code per pixel (Ojala 2002): 0..8 ones, 9 other.

    A pattern is uniform when its circular bit string has at most two 0/1 transitions;
    its code is then its number of ones (neighbours >= centre).
    """
    padded = np.asarray(cv2.copyMakeBorder(grey, 1, 1, 1, 1, cv2.BORDER_REPLICATE), np.uint8)
    centre = padded[1:-1, 1:-1]
    bits = [(_neighbour(padded, k) >= centre) for k in range(8)]
    ones = np.sum(bits, axis=0)
    transitions = np.sum([bits[k] != bits[(k + 1) % 8] for k in range(8)], axis=0)
    codes: NDArray[np.uint8] = np.where(transitions <= 2, ones, 9).astype(np.uint8)
    return codes


def rgb_codes(bgr: NDArray[np.uint8]) -> NDArray[np.uint8]:
    """RGB 3x3x3 bin per pixel: r * 9 + g * 3 + b, each channel in thirds of 0..255."""
    third = (np.arange(256) * 3 // 256).astype(np.uint8)
    q = np.asarray(cv2.LUT(bgr, third), dtype=np.uint8)
    return np.asarray(q[..., 2] * 9 + q[..., 1] * 3 + q[..., 0], dtype=np.uint8)


# grey level 0..255 -> colour bin 0..26, for `grey_codes`
_GREY_LEVELS = (np.arange(256) * RGB_BINS // 256).astype(np.uint8)


def grey_codes(grey: NDArray[np.uint8]) -> NDArray[np.uint8]:
    """The colour histogram's 27 bins as grey levels (0..26): on a grey frame the RGB
    cube's diagonal would leave three of them in use."""
    return np.asarray(cv2.LUT(grey, _GREY_LEVELS), dtype=np.uint8)


class ColourTextureMaps:
    """Per-pixel colour and LBP codes over a region; 37-d box histograms (per band) on a grid.

    The 27 colour bins are RGB 3x3x3, or grey levels (`grey_codes`) with `grey`: a grey
    frame's RGB codes all lie on the cube's diagonal, three bins of the 27."""

    def __init__(
        self,
        frame: NDArray[np.uint8],
        region: tuple[int, int, int, int],
        grid: int,
        grey: bool = False,
    ) -> None:
        x0, y0, x1, y1 = region
        self.origin = (x0, y0)
        patch = frame[y0:y1, x0:x1]
        grey_patch = to_grey(patch)
        codes = grey_codes(grey_patch) if grey else rgb_codes(to_bgr(patch))
        # one code image: colour bin 0..26 in the low part, LBP code 0..9 after it; a border
        # of an "outside" value counted by neither histogram
        self._rgb = cv2.copyMakeBorder(codes, 1, 1, 1, 1, cv2.BORDER_CONSTANT, value=RGB_BINS)
        self._lbp = cv2.copyMakeBorder(
            lbp_riu2(grey_patch), 1, 1, 1, 1, cv2.BORDER_CONSTANT, value=LBP_BINS
        )
        self._grid = grid

    def histograms(self, boxes: FloatArray, parts: int = 1) -> FloatArray:
        """N x 37 * parts: per horizontal band of the box (top first) the RGB histogram (27)
        then the LBP histogram (10); each band's two histograms sum to 1 / parts."""
        n, g = boxes.shape[0], self._grid
        u = (np.arange(g) + 0.5) / g - 0.5
        h, w = self._rgb.shape[0] - 2, self._rgb.shape[1] - 2
        xs = np.floor(boxes[:, 0:1] - self.origin[0] + 1 + boxes[:, 2:3] * u[None, :])
        ys = np.floor(boxes[:, 1:2] - self.origin[1] + 1 + boxes[:, 3:4] * u[None, :])
        xi = np.clip(xs, 0, w + 1).astype(np.intp)
        yi = np.clip(ys, 0, h + 1).astype(np.intp) * (w + 2)
        flat = (yi[:, :, None] + xi[:, None, :]).reshape(n, -1)
        # one histogram per (box, band): a sample row's band is row * parts // grid
        band = np.repeat(np.arange(g) * parts // g, g)
        base = np.arange(n)[:, None] * parts + band[None, :]
        rgb = self._rgb.ravel().take(flat).astype(np.intp) + base * (RGB_BINS + 1)
        lbp = self._lbp.ravel().take(flat).astype(np.intp) + base * (LBP_BINS + 1)
        size = n * parts
        h_rgb = np.bincount(rgb.ravel(), minlength=size * (RGB_BINS + 1)).reshape(size, -1)
        h_lbp = np.bincount(lbp.ravel(), minlength=size * (LBP_BINS + 1)).reshape(size, -1)
        out = np.concatenate([h_rgb[:, :RGB_BINS], h_lbp[:, :LBP_BINS]], axis=1)
        return out.reshape(n, -1).astype(np.float64) / float(g * g)
