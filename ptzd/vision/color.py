"""Colour likelihood (Chang 2020, seed 002 eqs. 6-11 and 16), vectorised.

A box's colour model is an Epanechnikov-weighted histogram of quantised HSV colours
(6 x 6 x 6 = 216 bins by default). Instead of visiting every pixel of every particle box,
each box is sampled on a fixed `grid_cols x grid_rows` grid of normalised positions whose
kernel weights are computed once: all N histograms then come from one gather into a
bin-index image (computed only over the particles' bounding region) and one `np.bincount`
over `particle * (bins + 1) + bin`. Samples outside the frame fall into an extra
"outside" bin that no target model has, so a box half out of the frame loses similarity
instead of being judged on its visible half alone.

Beyond the seed: grey and near-black pixels can be collapsed into hue bin 0 (their hue is
noise); a pixel's weight can be split between its two nearest value bins (soft value
binning: a colour on a bin edge does not flip between bins with the shading); and the
target model can be background-weighted: colours frequent in a ring around the target are
down-weighted (Ning et al.'s corrected background-weighted histogram applied to the
target model only).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from typing import cast

import cv2
import numpy as np
from numpy.typing import NDArray

from ptzd.vision.config import ColorConfig, GmmConfig
from ptzd.vision.gmm import GmmTargetModel
from ptzd.vision.likelihood import FloatArray, Frame

# A bin image is H x W bin indices, or with soft value bins 3 x H x W: the lower bin, the
# upper bin and the upper bin's share of the pixel (0..255).
BinImage = NDArray[np.uint8] | NDArray[np.int16]
Step = tuple[int, int]
# Background colours rarer than this share of the ring keep full weight in the target model.
_BACKGROUND_FLOOR = 0.02
# Coarsest pixel step of the bin image for large boxes (see ColorLikelihood._bin_step).
_MAX_BIN_STEP = 4
# The background ring is re-measured every this many adapt() calls (it changes slowly).
_RING_EVERY = 3


@dataclass(frozen=True, eq=False)
class BinLuts:
    """Per-channel lookup tables from 8-bit full-range HSV to a bin index."""

    hue: NDArray[np.int16]
    saturation: NDArray[np.int16]
    value: NDArray[np.int16]  # with soft value bins: the lower of the two
    collapse: NDArray[np.int16] | None  # bin -> bin with hue dropped where it is noise
    n_bins: int
    # soft value bins (ColorConfig.value_blend): the upper value bin, and its share of the
    # pixel in 1/255ths; None: hard bins
    value_upper: NDArray[np.int16] | None = None
    upper_share: NDArray[np.uint8] | None = None

    def value_terms(self, upper: bool) -> NDArray[np.int16]:
        """The value channel's bin terms: the upper soft bin's if `upper` and bins are soft."""
        return self.value_upper if upper and self.value_upper is not None else self.value


def make_luts(config: ColorConfig) -> BinLuts:
    """Lookup tables for `config`'s quantisation: bin = h * (S * V) + s * V + v.

    Soft value bins (`value_blend` z > 0): level L sits at c = (L + 0.5) V / 256 - 0.5 in
    value bins, whose centres are the integers, f = c - floor(c) past the lower one. The
    upper bin floor(c) + 1 takes clip((f - 0.5) / z + 0.5, 0, 1) of it, the lower the rest
    (both clipped to the bins there are): a level more than z / 2 bins from an edge stays
    whole in the bin it falls in, as with hard bins."""
    levels = np.arange(256)
    bh, bs, bv = config.bins_h, config.bins_s, config.bins_v
    hue = (levels * bh // 256 * (bs * bv)).astype(np.int16)
    sat = (levels * bs // 256 * bv).astype(np.int16)
    val = (levels * bv // 256).astype(np.int16)
    upper = share = None
    if config.value_blend > 0:
        position = (levels + 0.5) * bv / 256 - 0.5
        below = np.floor(position)
        upper_share = np.clip((position - below - 0.5) / config.value_blend + 0.5, 0.0, 1.0)
        val = np.clip(below, 0, bv - 1).astype(np.int16)
        upper = np.clip(below + 1, 0, bv - 1).astype(np.int16)
        share = np.round(upper_share * 255).astype(np.uint8)
    n_bins = bh * bs * bv
    collapse = None
    if config.achromatic_collapse:
        b = np.arange(n_bins)
        h, s, v = b // (bs * bv), (b // bv) % bs, b % bv
        h = np.where((s == 0) | (v == 0), 0, h)  # grey or dark: hue is noise
        s = np.where(v == 0, 0, s)  # dark: saturation is noise too
        collapse = (h * (bs * bv) + s * bv + v).astype(np.int16)
    return BinLuts(hue, sat, val, collapse, n_bins, upper, share)


_CHANNEL_SUM = np.ones((1, 3), np.float32)


@functools.lru_cache(maxsize=8)
def _channel_table(luts: BinLuts, upper: bool) -> NDArray[np.uint8]:
    """A 3-channel cv2.LUT table: H, S and V levels to their bin terms (n_bins < 256), with
    the upper soft value bin's term if `upper`."""
    terms = [luts.hue, luts.saturation, luts.value_terms(upper)]
    table = np.stack(terms, axis=1).astype(np.uint8)
    return table.reshape(256, 1, 3)


@functools.lru_cache(maxsize=8)
def _collapse_table(luts: BinLuts) -> NDArray[np.uint8]:
    table = np.zeros(256, np.uint8)
    if luts.collapse is not None:
        table[: luts.n_bins] = luts.collapse
    return table


def bin_image(bgr: Frame, luts: BinLuts) -> BinImage:
    """Bin index of every pixel of a BGR image (uint8 when the bins fit, else int16).

    Grey input (H x W or H x W x 1, e.g. a thermal camera) is read as achromatic BGR: every
    pixel falls in the value-only bins, so the colour tracker still runs on it.
    """
    if bgr.ndim == 2 or bgr.shape[2] == 1:
        bgr = np.asarray(cv2.cvtColor(bgr, cv2.COLOR_GRAY2BGR), dtype=np.uint8)
    hsv: Frame = np.asarray(cv2.cvtColor(bgr, cv2.COLOR_BGR2HSV_FULL), dtype=np.uint8)
    if luts.upper_share is not None and luts.n_bins < 256:
        return _soft_bin_planes(hsv, luts)
    lower = _bin_plane(hsv, luts, upper=False)
    if luts.upper_share is None:
        return lower
    share = luts.upper_share[hsv[..., 2]].astype(lower.dtype, copy=False)
    return cast(BinImage, np.stack([lower, _bin_plane(hsv, luts, upper=True), share]))


def _soft_bin_planes(hsv: Frame, luts: BinLuts) -> BinImage:
    """`bin_image`'s three soft planes (lower bin, upper bin, upper share) in uint8, from
    one pass of the per-channel tables: the upper bin before the achromatic collapse is
    the lower one plus the value step (0 where the value clips at either end, else 1)."""
    assert luts.upper_share is not None and luts.value_upper is not None
    value = cv2.extractChannel(hsv, 2)
    fine = cv2.transform(cv2.LUT(hsv, _channel_table(luts, False)), _CHANNEL_SUM)
    stepped = cv2.add(fine, cv2.LUT(value, _value_step_table(luts)))
    lower, upper = fine, stepped
    if luts.collapse is not None:
        table = _collapse_table(luts)
        lower, upper = cv2.LUT(fine, table), cv2.LUT(stepped, table)
    share = cv2.LUT(value, luts.upper_share)
    planes = [
        np.asarray(plane, dtype=np.uint8).reshape(hsv.shape[:2]) for plane in (lower, upper, share)
    ]
    return cast(BinImage, np.stack(planes))


@functools.lru_cache(maxsize=8)
def _value_step_table(luts: BinLuts) -> NDArray[np.uint8]:
    """Per value level: the upper soft value bin's term less the lower one's (0 or 1)."""
    return (luts.value_terms(True) - luts.value).astype(np.uint8)


def _bin_plane(hsv: Frame, luts: BinLuts, *, upper: bool) -> BinImage:
    """Bin index of every pixel of an HSV image; with soft value bins the lower or upper."""
    if luts.n_bins < 256:
        # three OpenCV uint8 kernels: per-channel LUT to the bin terms, their sum (never
        # above n_bins - 1 < 255), the achromatic collapse
        terms = cv2.LUT(hsv, _channel_table(luts, upper))
        bins8 = cv2.transform(terms, _CHANNEL_SUM)
        if luts.collapse is not None:
            bins8 = cv2.LUT(bins8, _collapse_table(luts))
        out8: NDArray[np.uint8] = np.asarray(bins8, dtype=np.uint8).reshape(hsv.shape[:2])
        return out8
    bins: NDArray[np.int16] = (
        luts.hue[hsv[..., 0]] + luts.saturation[hsv[..., 1]] + luts.value_terms(upper)[hsv[..., 2]]
    )
    if luts.collapse is not None:
        bins = luts.collapse[bins]
    return bins


@dataclass(frozen=True, eq=False)
class SampleGrid:
    """Normalised sample offsets in a box (-0.5..0.5), their weights and stripe ("part").

    The rows are split top to bottom into `parts` horizontal stripes with a histogram each
    (a pedestrian's top and legs); each stripe's weights sum to one.
    """

    u: FloatArray  # (cols,) horizontal offsets, in box widths from the centre
    v: FloatArray  # (rows,) vertical offsets, in box heights from the centre
    weights: FloatArray  # (rows, cols)
    part: NDArray[np.intp]  # (rows,) stripe of each row
    parts: int
    # the samples `box_histograms` visits: those of non-zero weight (an ellipse inscribed
    # in the box leaves 21 % of the grid at zero, the contrast ring's box 44 %), row-major
    sample_rows: NDArray[np.intp] = field(init=False, repr=False)
    sample_cols: NDArray[np.intp] = field(init=False, repr=False)
    # `box_histograms`' arrays for n boxes, kept with the grid so that they go with it: a
    # module-level cache keyed by grid held up to 16 of them (1.2 MB each at 300 particles)
    # for the grids of locks long ended, and the heap rose and fell by 10 MB with them
    _per_n: dict[tuple[int, int], _PerN] = field(default_factory=dict, init=False, repr=False)

    def __post_init__(self) -> None:
        rows, cols = np.nonzero(self.weights)
        object.__setattr__(self, "sample_rows", rows.astype(np.intp))
        object.__setattr__(self, "sample_cols", cols.astype(np.intp))


@dataclass(eq=False)
class _PerN:
    """`box_histograms`' arrays for n boxes on one grid (see `_per_n_arrays`)."""

    offsets: NDArray[np.intp]  # (n, samples) histogram column of each sample's bin 0
    weights: FloatArray  # the visited samples' weights repeated n times
    # soft value bins: room for both halves of every sample's column and weight, for
    # `_SOFT_CHUNK` boxes, reused frame after frame (see `_soft_histograms`)
    soft_columns: NDArray[np.intp] | None = None
    soft_weights: FloatArray | None = None


def _offsets(n: int, extent: float = 1.0) -> FloatArray:
    return ((np.arange(n) + 0.5) / n - 0.5) * extent


def _split(weights: FloatArray, parts: int) -> tuple[FloatArray, NDArray[np.intp]]:
    rows = weights.shape[0]
    part = (np.arange(rows) * parts // rows).astype(np.intp)
    sums = np.bincount(part, weights=weights.sum(axis=1), minlength=parts)
    return weights / sums[part][:, None], part


def kernel_grid(
    cols: int,
    rows: int,
    kernel: str = "ellipse",
    aspect: float = 1.0,
    parts: int = 1,
    top_max_aspect: float = 0.0,
) -> SampleGrid:
    """Epanechnikov-weighted grid (seed eq. 6; the constant 3/4 cancels in the normalisation).

    `ellipse`: radius 1 on the ellipse inscribed in the box (Comaniciu, Nummiaro);
    `diagonal`: the seed's normalisation a = sqrt(w^2 + h^2) for a box of aspect w/h.
    With several parts each stripe gets its own kernel, centred on the stripe. The top
    stripe's ellipse of a box wider than `top_max_aspect` (w/h; 0: no limit) is that many
    box heights wide, in the middle of the box (ColorConfig.top_max_aspect).
    """
    u = _offsets(cols)
    rows_per_part = rows // parts
    v_local = _offsets(rows_per_part)  # within one stripe, -0.5..0.5 of its height
    v = (np.arange(rows) + 0.5) / rows - 0.5
    if kernel == "ellipse":
        squeeze = np.ones((rows, 1))
        if parts > 1 and 0 < top_max_aspect < aspect:
            squeeze[:rows_per_part] = aspect / top_max_aspect
        r2 = (2 * squeeze * u[None, :]) ** 2 + (2 * np.tile(v_local, parts)[:, None]) ** 2
    else:
        stripe_aspect = aspect * parts
        r2 = ((u[None, :] * stripe_aspect) ** 2 + np.tile(v_local, parts)[:, None] ** 2) / (
            stripe_aspect**2 + 1.0
        )
    weights, part = _split(np.clip(1.0 - r2, 0.0, None), parts)
    return SampleGrid(u, v, weights, part, parts)


def ring_grid(cols: int, rows: int, ring_scale: float) -> SampleGrid:
    """Uniform grid over a box `ring_scale` times larger, excluding the box itself."""
    u, v = _offsets(cols, ring_scale), _offsets(rows, ring_scale)
    inside = (np.abs(u[None, :]) < 0.5) & (np.abs(v[:, None]) < 0.5)
    weights, part = _split(np.where(inside, 0.0, 1.0), 1)
    return SampleGrid(u, v, weights, part, 1)


_PER_GRID = 4  # box counts kept per grid: the particles, one box, and room to spare


def _per_n_arrays(grid: SampleGrid, n: int, n_bins: int) -> _PerN:
    """For n boxes on `grid`: the histogram column offset of every visited sample (box *
    parts * (bins + 1) + part * (bins + 1)), and their weights repeated n times, contiguous
    (bincount wants a flat array). Kept for the last `_PER_GRID` (n, n_bins)."""
    key = (n, n_bins)
    found = grid._per_n.pop(key, None)  # re-inserted below: the dict is oldest first
    if found is None:
        rows, cols = grid.sample_rows, grid.sample_cols
        per_box = (np.arange(n, dtype=np.intp) * (grid.parts * (n_bins + 1)))[:, None]
        offsets = per_box + (grid.part[rows] * (n_bins + 1))[None, :]
        found = _PerN(offsets, np.tile(grid.weights[rows, cols], n))
        while len(grid._per_n) >= _PER_GRID:
            del grid._per_n[next(iter(grid._per_n))]
    grid._per_n[key] = found
    return found


def bins_for_region(
    frame: Frame, region: tuple[int, int, int, int], luts: BinLuts, step: Step = (1, 1)
) -> BinImage:
    """`pad_bins` of the bin image of `frame[y0:y1, x0:x1]`, every `step` = (sx, sy) pixel."""
    x0, y0, x1, y1 = region
    sx, sy = step
    return pad_bins(bin_image(frame[y0:y1:sy, x0:x1:sx], luts), luts.n_bins)


def pad_bins(bins: BinImage, n_bins: int) -> BinImage:
    """`bins` with a one-pixel border of the "outside" bin `n_bins`, for `box_histograms`
    (soft value bins: both bin planes; the upper share is 0 there)."""
    if bins.ndim == 3:
        lower, upper, share = bins
        planes = [_padded(lower, n_bins), _padded(upper, n_bins), _padded(share, 0)]
        return cast(BinImage, np.stack(planes))
    return _padded(bins, n_bins)


def _padded(plane: BinImage, value: int) -> BinImage:
    if plane.dtype == np.uint8:
        border = cv2.copyMakeBorder(plane, 1, 1, 1, 1, cv2.BORDER_CONSTANT, value=value)
        out: NDArray[np.uint8] = np.asarray(border, dtype=np.uint8)
        return out
    height, width = plane.shape
    padded = np.full((height + 2, width + 2), value, dtype=plane.dtype)
    padded[1:-1, 1:-1] = plane
    return padded


def box_histograms(
    padded: BinImage,
    origin: tuple[int, int],
    boxes: FloatArray,
    grid: SampleGrid,
    n_bins: int,
    step: Step = (1, 1),
) -> FloatArray:
    """Weighted histograms (N x parts x (n_bins + 1)) of `boxes` (cx, cy, w, h) on `grid`.

    `padded` is `pad_bins` of the bin image of the frame region whose top-left pixel is
    `origin` (x0, y0). Samples outside that region are clipped onto the border and so
    counted in the last ("outside") column, without masks. Each part sums to one.
    With `step` = (sx, sy) other than (1, 1) the bin image holds every sx-th column and
    sy-th row of the region (`bins_for_region`), and a sample takes the retained pixel at or
    above-left of it. A soft bin image (3 planes) splits each sample's weight between its
    lower and upper value bin.
    """
    n = boxes.shape[0]
    height, width = padded.shape[-2] - 2, padded.shape[-1] - 2
    if step == (1, 1):
        x0, y0 = origin[0] - 1, origin[1] - 1
        xs = np.floor(boxes[:, 0:1] - x0 + boxes[:, 2:3] * grid.u[None, :]).astype(np.intp)
        ys = np.floor(boxes[:, 1:2] - y0 + boxes[:, 3:4] * grid.v[None, :]).astype(np.intp)
    else:
        xs = np.floor((boxes[:, 0:1] - origin[0] + boxes[:, 2:3] * grid.u[None, :]) / step[0])
        ys = np.floor((boxes[:, 1:2] - origin[1] + boxes[:, 3:4] * grid.v[None, :]) / step[1])
        xs = xs.astype(np.intp) + 1
        ys = ys.astype(np.intp) + 1
    # (np.minimum/maximum: np.clip's Python wrapper costs more than the work at this size)
    np.minimum(np.maximum(xs, 0, out=xs), width + 1, out=xs)
    np.minimum(np.maximum(ys, 0, out=ys), height + 1, out=ys)
    ys *= width + 2
    # (zero-weight samples add nothing to a histogram: only the others are gathered)
    index = ys.take(grid.sample_rows, axis=1)
    index += xs.take(grid.sample_cols, axis=1)
    if padded.ndim == 3:
        return _soft_histograms(padded, index, grid, n_bins)
    stride = grid.parts * (n_bins + 1)
    per_n = _per_n_arrays(grid, n, n_bins)
    offsets, weights = per_n.offsets, per_n.weights
    np.add(offsets, padded.ravel().take(index), out=index)
    hist: FloatArray = np.bincount(index.ravel(), weights=weights, minlength=n * stride).astype(
        np.float64, copy=False
    )
    return hist.reshape(n, grid.parts, n_bins + 1)


# Boxes per pass of `_soft_histograms`. Its scratch is kept with the grid for this many
# boxes whatever the count: allocated afresh every frame (4.8 MB at 300 particles), glibc
# handed the pages back and faulted them in again, and the histograms took 9 ms, not 2;
# kept for every count, the frame-wide scan's (up to 600 boxes, a count that changes with
# the box size) held 10 MB a grid and the heap swung by 40 MB. 150: the default 300
# particles in two passes, 2.5 MB on the default grid.
_SOFT_CHUNK = 150


def _soft_histograms(
    padded: BinImage, index: NDArray[np.intp], grid: SampleGrid, n_bins: int
) -> FloatArray:
    """`box_histograms` on a soft bin image (lower bin, upper bin, upper share planes):
    both halves of every sample in one bincount, lower bins first, then upper ones, in
    passes of at most `_SOFT_CHUNK` boxes."""
    n, samples = index.shape
    stride = grid.parts * (n_bins + 1)
    per_n = _per_n_arrays(grid, min(n, _SOFT_CHUNK), n_bins)
    chunk = per_n.offsets.shape[0]
    if per_n.soft_columns is None or per_n.soft_weights is None:
        per_n.soft_columns = np.empty(2 * chunk * samples, np.intp)
        per_n.soft_weights = np.empty(2 * chunk * samples)
    lower, upper, share = padded.reshape(3, -1)
    passes: list[FloatArray] = []
    for start in range(0, n, chunk):
        boxes = index[start : start + chunk]
        m = boxes.shape[0]
        # (the first 2 m samples' room, as two contiguous halves)
        columns = per_n.soft_columns[: 2 * m * samples].reshape(2, m, samples)
        split = per_n.soft_weights[: 2 * m * samples].reshape(2, m * samples)
        weights = per_n.weights[: m * samples]
        np.add(per_n.offsets[:m], lower.take(boxes), out=columns[0])
        np.add(per_n.offsets[:m], upper.take(boxes), out=columns[1])
        np.multiply(weights, share.take(boxes.ravel()), out=split[1])
        split[1] *= 1.0 / 255
        np.subtract(weights, split[1], out=split[0])
        counts = np.bincount(columns.ravel(), weights=split.ravel(), minlength=m * stride)
        passes.append(counts.astype(np.float64, copy=False))
    # (joined at the end: writing each pass into a preallocated result made glibc hand
    # pages back and fault them in again every frame, 1.7 ms more at 300 particles)
    hist = passes[0] if len(passes) == 1 else np.concatenate(passes)
    return hist.reshape(n, grid.parts, n_bins + 1)


def bhattacharyya(p: FloatArray, q: FloatArray) -> FloatArray:
    """rho = sum_u sqrt(p_u q_u) (seed eq. 10), averaged over parts.

    `p` is N x parts x (m + 1) (the extra "outside" column never matches), `q` parts x m.
    """
    return bhattacharyya_sqrt(np.sqrt(p), sqrt_model(q))


def sqrt_model(q: FloatArray) -> FloatArray:
    """sqrt(q) (parts x m) as a flat vector with a zero "outside" column per part, divided
    by the number of parts: `bhattacharyya_sqrt`'s operand, computed once per model."""
    parts, m = q.shape
    out = np.zeros((parts, m + 1))
    out[:, :m] = np.sqrt(q) / parts
    return out.ravel()


def bhattacharyya_sqrt(sqrt_p: FloatArray, sqrt_q: FloatArray) -> FloatArray:
    """`bhattacharyya` from sqrt(p) (N x parts x (m + 1)) and `sqrt_model(q)`: one matvec."""
    rho: FloatArray = sqrt_p.reshape(sqrt_p.shape[0], -1) @ sqrt_q
    return rho


def background_weights(ring: FloatArray, floor: float = _BACKGROUND_FLOOR) -> FloatArray:
    """v_u = min(o* / o_u, 1): colours common around the target count less.

    o* is the smallest non-zero ring share, but never below `floor` so a noisy ring does
    not wipe out every colour but the rarest.
    """
    nonzero = ring[ring > 0]
    o_star = max(float(nonzero.min()) if nonzero.size else 1.0, floor)
    # a share that decayed to a subnormal number overflows the quotient: min(inf, 1) is
    # the right answer, so the warning (seen once in a 24-hour soak) is noise
    with np.errstate(divide="ignore", over="ignore"):
        return np.where(ring > 0, np.minimum(o_star / ring, 1.0), 1.0)


def _normalised(h: FloatArray) -> FloatArray:
    """Each row (last axis) scaled to sum to one; an empty row becomes uniform."""
    total = h.sum(axis=-1, keepdims=True)
    safe = np.where(total > 0, total, 1.0)
    return np.where(total > 0, h / safe, 1.0 / h.shape[-1])


class ColorLikelihood:
    """Seed 002's colour likelihood with the GMM-updated target model."""

    def __init__(self, config: ColorConfig, gmm: GmmConfig) -> None:
        self._config = config
        self._gmm_config = gmm
        self._luts = make_luts(config)
        self._ring_grid = ring_grid(32, 32, config.ring_scale)
        self._contrast_grid = ring_grid(8, 16, config.contrast_scale)
        self._grid = kernel_grid(
            config.grid_cols, config.grid_rows, config.kernel, parts=config.parts
        )
        self._gmm: GmmTargetModel | None = None
        self._ring: FloatArray | None = None
        # background_weights() of the ring, as last applied to the model (None: unweighted)
        self._background: FloatArray | None = None
        self._weighted_model: FloatArray = np.zeros((config.parts, self._luts.n_bins))
        # sqrt_model() of the weighted model, its part-mean and the plain model
        self._sqrt_weighted: FloatArray = sqrt_model(self._weighted_model)
        self._sqrt_weighted_mean: FloatArray = sqrt_model(self._weighted_model[:1])
        self._sqrt_model: FloatArray = sqrt_model(self._weighted_model)
        self._box: FloatArray = np.zeros(4)
        # Bin image of the current frame, reused across calls for the same frame.
        self._frame: Frame | None = None
        self._bins: BinImage = np.zeros((0, 0), np.int16)
        self._origin = (0, 0)
        self._step: Step = (1, 1)  # of the cached bin image (see _bin_step)
        self._region_end = (0, 0)
        self._adapted = 0  # adapt() calls since init()
        self._last: tuple[Frame | None, FloatArray, FloatArray] = (None, np.zeros(4), np.zeros(0))

    @property
    def n_bins(self) -> int:
        return self._luts.n_bins

    @property
    def model(self) -> FloatArray:
        """The current (GMM-updated, not background-weighted) target model, parts x bins."""
        if self._gmm is None:
            raise RuntimeError("init() first")
        return self._gmm.model

    # -- bin image over a region, cached per frame --------------------------------------

    def _region_of(self, frame: Frame, boxes: FloatArray) -> tuple[int, int, int, int]:
        height, width = frame.shape[:2]
        half = boxes[:, 2:] / 2
        lo = np.floor((boxes[:, :2] - half).min(axis=0))
        hi = np.ceil((boxes[:, :2] + half).max(axis=0))
        x0 = min(max(int(lo[0]), 0), width - 1)
        y0 = min(max(int(lo[1]), 0), height - 1)
        return (
            x0,
            y0,
            min(max(int(hi[0]) + 1, x0 + 1), width),
            min(max(int(hi[1]) + 1, y0 + 1), height),
        )

    def _bin_step(self) -> Step:
        """Pixel steps (sx, sy) of the bin image: the grid samples a box every w/cols x h/rows
        pixels anyway, so for large boxes converting every pixel is wasted (beyond the seed)."""
        cfg = self._config
        sx = min(max(int(self._box[2] / cfg.grid_cols), 1), _MAX_BIN_STEP)
        sy = min(max(int(self._box[3] / cfg.grid_rows), 1), _MAX_BIN_STEP)
        return sx, sy

    def _bins_for(self, frame: Frame, boxes: FloatArray) -> tuple[BinImage, tuple[int, int]]:
        x0, y0, x1, y1 = self._region_of(frame, boxes)
        if self._frame is frame:
            cx0, cy0 = self._origin
            cx1, cy1 = self._region_end
            if x0 >= cx0 and y0 >= cy0 and x1 <= cx1 and y1 <= cy1:
                return self._bins, self._origin
            x0, y0 = min(x0, cx0), min(y0, cy0)
            x1, y1 = max(x1, cx1), max(y1, cy1)
        else:
            self._step = self._bin_step()
        self._frame = frame
        self._bins = bins_for_region(frame, (x0, y0, x1, y1), self._luts, self._step)
        self._origin = (x0, y0)
        self._region_end = (x1, y1)
        return self._bins, self._origin

    def histograms(self, frame: Frame, boxes: FloatArray) -> FloatArray:
        """Kernel histograms (N x parts x (bins + 1); last column = outside) of `boxes`."""
        bins, origin = self._bins_for(frame, boxes)
        return box_histograms(bins, origin, boxes, self._grid, self.n_bins, self._step)

    def _ring_histogram(self, frame: Frame, box: FloatArray) -> FloatArray:
        scale = self._config.ring_scale
        outer = box[None, :] * np.array([1.0, 1.0, scale, scale])
        bins, origin = self._bins_for(frame, outer)
        ring = box_histograms(bins, origin, box[None, :], self._ring_grid, self.n_bins, self._step)[
            0, 0
        ]
        return _normalised(ring[: self.n_bins])

    def _reweight(self) -> None:
        assert self._gmm is not None
        q = self._gmm.model
        self._background = None
        if self._config.background_weighting and self._ring is not None:
            self._background = background_weights(self._ring)
            q = _normalised(q * self._background[None, :])
        self._weighted_model = q
        self._sqrt_weighted = sqrt_model(q)
        self._sqrt_weighted_mean = sqrt_model(q.mean(axis=0, keepdims=True))
        self._sqrt_model = sqrt_model(self._gmm.model)

    # -- Likelihood protocol --------------------------------------------------------------

    def init(self, frame: Frame, box: FloatArray) -> None:
        self._frame = None
        self._adapted = 0
        self._box = box.copy()  # before the histograms: it sets the bin image's step
        cfg = self._config
        self._grid = kernel_grid(
            cfg.grid_cols,
            cfg.grid_rows,
            cfg.kernel,
            aspect=float(box[2] / box[3]),
            parts=cfg.parts,
            top_max_aspect=cfg.top_max_aspect,
        )
        target = self.histograms(frame, box[None, :])[0]
        self._gmm = GmmTargetModel(_normalised(target[:, : self.n_bins]), self._gmm_config)
        self._ring = self._ring_histogram(frame, box) if cfg.background_weighting else None
        self._reweight()

    def log_likelihood(self, frame: Frame, boxes: FloatArray) -> FloatArray:
        cfg = self._config
        grow = max(cfg.ring_scale if cfg.background_weighting else 1.0, cfg.contrast_scale)
        # one bin image for the particles, their contrast rings and the ring adapt() needs
        bins, origin = self._bins_for(
            frame, np.vstack([boxes, self._box[None, :]]) * [1, 1, grow, grow]
        )
        hist = box_histograms(bins, origin, boxes, self._grid, self.n_bins, self._step)
        rho = bhattacharyya_sqrt(np.sqrt(hist, out=hist), self._sqrt_weighted)
        if cfg.scale_contrast > 0:
            ring = box_histograms(bins, origin, boxes, self._contrast_grid, self.n_bins, self._step)
            ring_rho = bhattacharyya_sqrt(np.sqrt(ring, out=ring), self._sqrt_weighted_mean)
            rho -= cfg.scale_contrast * ring_rho
        return -(1.0 - rho) / (2.0 * cfg.sigma * cfg.sigma)

    def part_similarities(self, frame: Frame, box: FloatArray) -> FloatArray:
        hist = self.histograms(frame, box[None, :])
        self._last = (frame, box.copy(), hist[0])
        if self._config.weighted_confidence and self._background is not None:
            return self._weighted_similarities(hist[0], self._background)
        parts = self._config.parts
        # per part: sum_u sqrt(p_u q_u); `_sqrt_model` carries a 1/parts factor (the mean)
        terms = np.sqrt(hist[0]) * self._sqrt_model.reshape(parts, -1)
        rho: FloatArray = np.clip(parts * terms.sum(axis=1), 0.0, 1.0)
        return rho

    def _weighted_similarities(self, hist: FloatArray, background: FloatArray) -> FloatArray:
        """Per part, the box's histogram weighted by `background` like the model, against the
        weighted model. The weighted in-box colours keep their total share of the box, so
        the share outside the frame (the last column) still costs what it did."""
        inside = hist[:, : self.n_bins]
        weighted = inside * background[None, :]
        kept = weighted.sum(axis=1, keepdims=True)
        # (a part with nothing kept is all zeros: any finite scale leaves it so)
        weighted *= inside.sum(axis=1, keepdims=True) / np.where(kept > 0, kept, 1.0)
        rho: FloatArray = np.clip(np.sqrt(weighted * self._weighted_model).sum(axis=1), 0.0, 1.0)
        return rho

    def similarity(self, frame: Frame, box: FloatArray) -> float:
        """The mean of `part_similarities`: the seed's rho (eq. 10), averaged over parts."""
        return float(self.part_similarities(frame, box).mean())

    def adapt(self, frame: Frame, box: FloatArray) -> None:
        if self._gmm is None:
            raise RuntimeError("init() first")
        last_frame, last_box, last_hist = self._last
        if last_frame is frame and np.array_equal(last_box, box):
            observed = last_hist  # similarity() just measured this very box
        else:
            observed = self.histograms(frame, box[None, :])[0]
        self._gmm.update(_normalised(observed[:, : self.n_bins]))
        self._adapted += 1
        if self._ring is not None and self._adapted % _RING_EVERY == 0:
            # every _RING_EVERY frames at the compounded rate: the same time constant as
            # every frame at `background_rate`, for a third of the work
            rate = 1.0 - (1.0 - self._config.background_rate) ** _RING_EVERY
            self._ring = (1.0 - rate) * self._ring + rate * self._ring_histogram(frame, box)
        self._box = box.copy()
        self._reweight()

    def rescale(self, factor: float) -> None:
        # Normalised histograms are scale-free; only the remembered box size changes.
        self._box = self._box * np.array([1.0, 1.0, factor, factor])


# Channels of a colour frame differing by at most this much are a grey picture (a thermal
# camera's stream decoded to BGR): its colour model would be the value bins alone.
_GREY_SPREAD = 2


def is_colour(frame: Frame, box: FloatArray) -> bool:
    """Whether `frame` shows colour in `box` (cx, cy, w, h): three channels that differ."""
    if frame.ndim == 2 or frame.shape[2] == 1:
        return False
    height, width = frame.shape[:2]
    x0, x1 = np.clip([box[0] - box[2] / 2, box[0] + box[2] / 2 + 1], 0, width).astype(int)
    y0, y1 = np.clip([box[1] - box[3] / 2, box[1] + box[3] / 2 + 1], 0, height).astype(int)
    patch = frame[y0:y1, x0:x1].astype(np.int16)
    if patch.size == 0:
        return False
    spread = patch.max(axis=2) - patch.min(axis=2)
    return bool(spread.max() > _GREY_SPREAD)


class ColourVote:
    """The colour tracker's likelihood as a factor on a learned tracker's particle weights.

    rf's forests see grey levels and texture only, svm's a coarse 27-bin RGB histogram;
    this adds the colour tracker's GMM-updated, background-weighted HSV model. Off on grey
    frames (decided at `init`): there its six value bins only blur the learned model.
    Its value bins are hard (the seed's) whatever `color.value_blend` says: rf's and svm's
    rules were each measured with hard ones, soft ones only on the colour tracker."""

    def __init__(self, color: ColorConfig, gmm: GmmConfig, weight: float) -> None:
        self._likelihood = ColorLikelihood(color.model_copy(update={"value_blend": 0.0}), gmm)
        self._weight = weight
        self.active = False

    def init(self, frame: Frame, box: FloatArray) -> None:
        self.active = self._weight > 0 and is_colour(frame, box)
        if self.active:
            self._likelihood.init(frame, box)

    def weigh(self, frame: Frame, boxes: FloatArray, weights: FloatArray) -> FloatArray:
        """`weights` (one per row of `boxes`) times the colour likelihood ** weight."""
        if not self.active:
            return weights
        log = self._likelihood.log_likelihood(frame, boxes)
        weighted: FloatArray = weights * np.exp(self._weight * (log - log.max()))
        return weighted

    def best(self, frame: Frame, boxes: FloatArray) -> tuple[int, float]:
        """The row of `boxes` (non-empty) the colour model likes best, and its similarity."""
        best = int(np.argmax(self._likelihood.log_likelihood(frame, boxes)))
        return best, self._likelihood.similarity(frame, boxes[best])

    def similarity(self, frame: Frame, box: FloatArray) -> float:
        """The colour model's similarity at centre-form `box` (1.0 when off)."""
        return self._likelihood.similarity(frame, box) if self.active else 1.0

    def agrees(self, frame: Frame, box: FloatArray, threshold: float) -> bool:
        """The colour model's similarity at `box` is at least `threshold` (True when off)."""
        return self.similarity(frame, box) >= threshold

    def adapt(self, frame: Frame, box: FloatArray) -> None:
        if self.active:
            self._likelihood.adapt(frame, box)

    def rescale(self, factor: float) -> None:
        if self.active:
            self._likelihood.rescale(factor)
