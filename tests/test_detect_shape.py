"""The seed-002 shape feature and codebook (eqs. 4-5) against hand-computed values."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from ptzd.vision.detect.codebook import Codebook, CodebookError, lbg_codebook, train_codebook
from ptzd.vision.detect.shape import (
    EMPTY_ROW_X,
    column_histogram,
    full_profile,
    normalise_silhouette,
    row_boundaries,
    select_rows,
    shape_feature,
)


def _pawn() -> np.ndarray:
    """40x20: a 4-wide head (rows 0-9, cols 8-11) on a 12-wide body (rows 10-39, cols 4-15)."""
    mask = np.zeros((40, 20), dtype=bool)
    mask[0:10, 8:12] = True
    mask[10:40, 4:16] = True
    return mask


def test_boundaries_and_histogram_by_hand() -> None:
    left, right = row_boundaries(_pawn())
    assert left.tolist() == [8.0] * 10 + [4.0] * 30
    assert right.tolist() == [11.0] * 10 + [15.0] * 30
    # bands of 2 columns: cols 4-7 filled on 30 of 40 rows -> 60/80 -> 7.5; cols 8-11 all -> 10
    assert column_histogram(_pawn()).tolist() == [0, 0, 7.5, 7.5, 10, 10, 7.5, 7.5, 0, 0]


def test_feature_reads_the_chosen_rows() -> None:
    left_rows = np.array([0, 1, 2, 3, 4, 20, 21, 22, 23, 24])
    right_rows = np.array([5, 6, 7, 8, 9, 30, 31, 32, 33, 34])
    feat = shape_feature(_pawn(), left_rows, right_rows)
    expected = (
        [8.0] * 5 + [4.0] * 5 + [11.0] * 5 + [15.0] * 5 + [0, 0, 7.5, 7.5, 10, 10, 7.5, 7.5, 0, 0]
    )
    assert feat.shape == (30,)
    assert feat.tolist() == expected


def test_empty_rows_sit_at_the_centre() -> None:
    mask = _pawn()
    mask[0:3] = False
    left, right = row_boundaries(mask)
    assert left[:3].tolist() == [EMPTY_ROW_X] * 3 and right[:3].tolist() == [EMPTY_ROW_X] * 3


def test_normalisation_of_a_scaled_silhouette() -> None:
    big = np.kron(_pawn(), np.ones((3, 3), dtype=bool))  # 120x60, same shape
    assert np.array_equal(normalise_silhouette(big), _pawn())
    with pytest.raises(ValueError):
        normalise_silhouette(np.zeros((0, 5), dtype=bool))


def test_rows_with_lowest_training_deviation_are_selected() -> None:
    rng = np.random.default_rng(0)
    profiles = np.tile(full_profile(_pawn()), (50, 1))
    jitter = np.ones(80)
    jitter[[3, 7, 11, 12, 13, 14, 15, 16, 17, 18]] = 0.0  # left side: these rows never move
    jitter[[40 + r for r in (20, 21, 22, 23, 24, 25, 26, 27, 28, 39)]] = 0.0
    profiles[:, :80] += rng.normal(0, 1, (50, 80)) * jitter
    left, right = select_rows(profiles.astype(np.float32))
    assert left.tolist() == [3, 7, 11, 12, 13, 14, 15, 16, 17, 18]
    assert right.tolist() == [20, 21, 22, 23, 24, 25, 26, 27, 28, 39]


def test_distortion_is_l1_to_the_nearest_code_word() -> None:
    words = np.zeros((2, 30), dtype=np.float32)
    words[1] = 2.0
    book = Codebook(words, np.arange(10), np.arange(10), threshold=10.0)
    x = np.full((1, 30), 1.5, dtype=np.float32)
    x[0, 0] = 5.0
    # to word 0: 29*1.5 + 5 = 48.5; to word 1: 29*0.5 + 3 = 17.5 -> eq. 5 picks 17.5
    assert book.distortion(x).tolist() == [17.5]


def test_lbg_finds_separated_clusters_and_is_seeded() -> None:
    rng = np.random.default_rng(1)
    a = rng.normal(0, 0.3, (200, 30)) + 2
    b = rng.normal(0, 0.3, (200, 30)) + 12
    feats = np.concatenate([a, b]).astype(np.float32)
    words = lbg_codebook(feats, 2, seed=3)
    centres = sorted(float(w.mean()) for w in words)
    assert centres[0] == pytest.approx(2, abs=0.2) and centres[1] == pytest.approx(12, abs=0.2)
    assert np.array_equal(words, lbg_codebook(feats, 2, seed=3))


def test_train_save_load_round_trip(tmp_path: Path) -> None:
    from ptzd.vision.detect.figures import walker_silhouette

    profiles = np.stack(
        [
            full_profile(normalise_silhouette(walker_silhouette(h, p)))
            for h in (60, 90, 140)
            for p in np.linspace(0, 6.2, 24)
        ]
    )
    book = train_codebook(profiles, size=8, seed=0, provenance="test")
    path = tmp_path / "cb.npz"
    book.save(path)
    again = Codebook.load(path)
    assert np.array_equal(again.codewords, book.codewords)
    assert again.threshold == book.threshold and again.provenance == "test"
    # the training walkers are human to it; a filled box is not
    feats = np.stack(
        [
            shape_feature(
                normalise_silhouette(walker_silhouette(110, 1.0)), book.left_rows, book.right_rows
            )
        ]
    )
    assert book.distortion(feats)[0] < book.threshold
    box = np.ones((80, 40), dtype=bool)
    box_feat = shape_feature(normalise_silhouette(box), book.left_rows, book.right_rows)
    assert book.distortion(box_feat[None])[0] > book.threshold


def test_bad_codebook_files_raise(tmp_path: Path) -> None:
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a codebook")
    with pytest.raises(CodebookError) as info:
        Codebook.load(bad)
    assert info.value.path == str(bad)
    with pytest.raises(CodebookError):
        Codebook.load(tmp_path / "missing.npz")


def test_shipped_codebook_loads_with_provenance() -> None:
    book = Codebook.load_default()
    assert book.codewords.shape == (32, 30)
    summary = book.summary()
    provenance = summary["provenance"]
    assert isinstance(provenance, dict)
    assert str(provenance["command"]).startswith("ptzd codebook train --source synthetic:")
