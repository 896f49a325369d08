"""The seed-002 shape feature of a silhouette (Chang et al. 2020, sec. 3.1, Fig. 5).

A candidate region's binary silhouette is normalised to 20x40 (width x height). For each of
the 40 rows we read the x of the leftmost and of the rightmost silhouette pixel; the feature
keeps 10 rows per side, the rows whose boundary varied least over the training silhouettes
(the seed: top and bottom rows are too changeable to be used), giving 20 coordinates. The
seed's "10 bins of the histogram" are not defined beyond Fig. 5; we take them as the
silhouette's column histogram: the 20 columns in 10 bands of 2, each bin the fraction of its
2x40 pixels that belong to the silhouette, scaled to 0..10 so a bin weighs about as much in
the L1 distortion (eq. 4) as a boundary coordinate (0..19). It is the horizontal mass
profile, which the boundary coordinates do not capture (a human is heavy in the middle
columns; a box fills them all).
"""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray

NORM_WIDTH = 20
NORM_HEIGHT = 40
ROWS_PER_SIDE = 10
HIST_BINS = 10
HIST_SCALE = 10.0
FEATURE_DIM = 2 * ROWS_PER_SIDE + HIST_BINS  # 30
EMPTY_ROW_X = (NORM_WIDTH - 1) / 2.0
"""Both boundaries of a row with no silhouette pixel: a zero-width row at the centre."""

FloatArray = NDArray[np.float32]
Mask = NDArray[np.bool_]


def normalise_silhouette(mask: NDArray[np.generic]) -> Mask:
    """Resize a cropped silhouette (non-zero = object) to 40 rows x 20 columns.

    Area interpolation then a half threshold, so thin parts survive downscaling the way
    they would by majority vote rather than by nearest-neighbour sampling.
    """
    if mask.ndim != 2 or mask.shape[0] == 0 or mask.shape[1] == 0:
        raise ValueError(f"silhouette must be a non-empty 2-D mask, got shape {mask.shape}")
    as_u8 = (np.asarray(mask) != 0).astype(np.uint8) * 255
    resized = cv2.resize(as_u8, (NORM_WIDTH, NORM_HEIGHT), interpolation=cv2.INTER_AREA)
    out: Mask = resized >= 128
    return out


def row_boundaries(norm: Mask) -> tuple[FloatArray, FloatArray]:
    """Left and right boundary x of every row of a normalised 40x20 silhouette."""
    if norm.shape != (NORM_HEIGHT, NORM_WIDTH):
        raise ValueError(f"expected a {NORM_HEIGHT}x{NORM_WIDTH} mask, got {norm.shape}")
    filled = norm.any(axis=1)
    left = np.argmax(norm, axis=1).astype(np.float32)
    right = (NORM_WIDTH - 1 - np.argmax(norm[:, ::-1], axis=1)).astype(np.float32)
    left[~filled] = EMPTY_ROW_X
    right[~filled] = EMPTY_ROW_X
    return left, right


def column_histogram(norm: Mask) -> FloatArray:
    """Fill of the 10 two-column bands, each scaled to 0..HIST_SCALE."""
    bands = norm.reshape(NORM_HEIGHT, HIST_BINS, NORM_WIDTH // HIST_BINS)
    fill = bands.sum(axis=(0, 2), dtype=np.float32) / float(bands.shape[0] * bands.shape[2])
    out: FloatArray = (fill * HIST_SCALE).astype(np.float32)
    return out


def full_profile(norm: Mask) -> FloatArray:
    """All 40 left, all 40 right boundaries and the 10 bins (90 values): rows not yet chosen."""
    left, right = row_boundaries(norm)
    return np.concatenate([left, right, column_histogram(norm)]).astype(np.float32)


def shape_feature(
    norm: Mask, left_rows: NDArray[np.intp], right_rows: NDArray[np.intp]
) -> FloatArray:
    """The 30-d feature: left x at `left_rows`, right x at `right_rows`, then the histogram."""
    left, right = row_boundaries(norm)
    return np.concatenate([left[left_rows], right[right_rows], column_histogram(norm)]).astype(
        np.float32
    )


def select_rows(profiles: FloatArray) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """The 10 rows per side whose boundary x has the lowest standard deviation in training.

    `profiles` is (N, 90) from `full_profile`. Ties go to the upper row; returned rows are
    sorted top to bottom so the feature reads like the silhouette.
    """
    if profiles.ndim != 2 or profiles.shape[1] != 2 * NORM_HEIGHT + HIST_BINS:
        raise ValueError(
            f"profiles must be (N, {2 * NORM_HEIGHT + HIST_BINS}), got {profiles.shape}"
        )
    if profiles.shape[0] < 2:
        raise ValueError("need at least 2 training silhouettes to rank rows by deviation")
    std = profiles[:, : 2 * NORM_HEIGHT].std(axis=0)
    left = np.sort(np.argsort(std[:NORM_HEIGHT], kind="stable")[:ROWS_PER_SIDE])
    right = np.sort(np.argsort(std[NORM_HEIGHT:], kind="stable")[:ROWS_PER_SIDE])
    return left.astype(np.intp), right.astype(np.intp)


def features_from_profiles(
    profiles: FloatArray, left_rows: NDArray[np.intp], right_rows: NDArray[np.intp]
) -> FloatArray:
    """(N, 30) features from (N, 90) profiles, the same selection `shape_feature` makes."""
    cols = np.concatenate(
        [left_rows, NORM_HEIGHT + right_rows, 2 * NORM_HEIGHT + np.arange(HIST_BINS)]
    )
    out: FloatArray = profiles[:, cols].astype(np.float32)
    return out
