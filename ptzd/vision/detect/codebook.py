"""Codebook matching of shape features (seed 002, sec. 3.1, eqs. 4-5) and its training.

A codebook is N code words in the 30-d feature space plus the rows the feature reads and the
distortion threshold. Distortion is the L1 distance (eq. 4); an object is human when the
distortion to the nearest code word (eq. 5) is below the threshold. Training is LBG
(Linde-Buzo-Gray: split every code word in two, then Lloyd iterations) with the centroid
taken as the per-dimension median, which is the point minimising the L1 distortion the
matcher uses (k-medians), so training and matching optimise the same quantity.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ptzd.vision.detect.shape import (
    FEATURE_DIM,
    NORM_HEIGHT,
    ROWS_PER_SIDE,
    FloatArray,
    features_from_profiles,
    select_rows,
)

DEFAULT_CODEBOOK = "codebook_default.npz"
_FORMAT_VERSION = 1


class CodebookError(ValueError):
    """A codebook file that cannot be read or is inconsistent; carries the path."""

    def __init__(self, path: str, reason: str) -> None:
        self.path = path
        self.reason = reason
        super().__init__(f"codebook {path}: {reason}")


@dataclass(frozen=True)
class Codebook:
    """Code words (K, 30), the feature's rows (10 left, 10 right) and the human threshold."""

    codewords: FloatArray
    left_rows: NDArray[np.intp]
    right_rows: NDArray[np.intp]
    threshold: float
    provenance: str = ""

    def __post_init__(self) -> None:
        if self.codewords.ndim != 2 or self.codewords.shape[1] != FEATURE_DIM:
            raise ValueError(f"code words must be (K, {FEATURE_DIM}), got {self.codewords.shape}")
        if self.codewords.shape[0] < 1:
            raise ValueError("a codebook needs at least one code word")
        for name, rows in (("left_rows", self.left_rows), ("right_rows", self.right_rows)):
            if rows.shape != (ROWS_PER_SIDE,) or rows.min() < 0 or rows.max() >= NORM_HEIGHT:
                raise ValueError(f"{name} must be {ROWS_PER_SIDE} rows in 0..{NORM_HEIGHT - 1}")
        if not self.threshold > 0:
            raise ValueError(f"threshold must be > 0, got {self.threshold}")

    def distortion(self, features: FloatArray) -> FloatArray:
        """Eq. 5 for each row of `features` (N, 30): L1 distance to the nearest code word."""
        feats = np.atleast_2d(features).astype(np.float32)
        # (N, 1, D) - (1, K, D): N and K are small (tens of blobs, tens of code words).
        dist = np.abs(feats[:, None, :] - self.codewords[None, :, :]).sum(axis=2)
        out: FloatArray = dist.min(axis=1)
        return out

    def save(self, path: str | Path) -> None:
        np.savez_compressed(
            path,
            version=np.int64(_FORMAT_VERSION),
            codewords=self.codewords.astype(np.float32),
            left_rows=self.left_rows.astype(np.int16),
            right_rows=self.right_rows.astype(np.int16),
            threshold=np.float64(self.threshold),
            provenance=np.str_(self.provenance),
        )

    @classmethod
    def load(cls, path: str | Path) -> Codebook:
        where = str(path)
        try:
            with np.load(path, allow_pickle=False) as data:
                version = int(data["version"])
                if version != _FORMAT_VERSION:
                    raise CodebookError(
                        where, f"format version {version}, expected {_FORMAT_VERSION}"
                    )
                return cls(
                    codewords=data["codewords"].astype(np.float32),
                    left_rows=data["left_rows"].astype(np.intp),
                    right_rows=data["right_rows"].astype(np.intp),
                    threshold=float(data["threshold"]),
                    provenance=str(data["provenance"]),
                )
        except CodebookError:
            raise
        except (OSError, KeyError, ValueError) as exc:
            raise CodebookError(where, str(exc)) from None

    @classmethod
    def load_default(cls) -> Codebook:
        """The codebook shipped in the package (see data/PROVENANCE.md)."""
        ref = resources.files("ptzd.vision.detect") / "data" / DEFAULT_CODEBOOK
        with resources.as_file(ref) as path:
            return cls.load(path)

    def summary(self) -> dict[str, object]:
        return {
            "codewords": int(self.codewords.shape[0]),
            "left_rows": [int(r) for r in self.left_rows],
            "right_rows": [int(r) for r in self.right_rows],
            "threshold": round(self.threshold, 3),
            "provenance": json.loads(self.provenance)
            if self.provenance.startswith("{")
            else self.provenance,
        }


def _assign(features: FloatArray, codewords: FloatArray) -> tuple[NDArray[np.intp], FloatArray]:
    """Nearest code word (L1) of every feature, in chunks so memory stays bounded."""
    labels = np.empty(features.shape[0], dtype=np.intp)
    dists = np.empty(features.shape[0], dtype=np.float32)
    step = max(1, 2_000_000 // max(1, codewords.shape[0] * FEATURE_DIM))
    for start in range(0, features.shape[0], step):
        chunk = features[start : start + step]
        d = np.abs(chunk[:, None, :] - codewords[None, :, :]).sum(axis=2)
        labels[start : start + step] = d.argmin(axis=1)
        dists[start : start + step] = d.min(axis=1)
    return labels, dists


def lbg_codebook(
    features: FloatArray,
    size: int,
    *,
    seed: int,
    epsilon: float = 0.01,
    max_iter: int = 30,
    tol: float = 1e-4,
) -> FloatArray:
    """LBG with L1 distortion and median centroids; returns at most `size` code words.

    Splitting perturbs each code word by +/- epsilon times the per-dimension spread plus a
    seeded jitter (so identical words still separate); a cell left empty by a split is
    re-seeded from the feature worst served by its code word.
    """
    if features.ndim != 2 or features.shape[0] == 0:
        raise ValueError("need a non-empty (N, D) feature array")
    if size < 1:
        raise ValueError("codebook size must be >= 1")
    rng = np.random.default_rng(seed)
    feats = features.astype(np.float32)
    spread = feats.std(axis=0) + 1e-3
    codewords = np.median(feats, axis=0, keepdims=True).astype(np.float32)
    while True:
        prev = np.inf
        for _ in range(max_iter):
            labels, dists = _assign(feats, codewords)
            total = float(dists.mean())
            for k in range(codewords.shape[0]):
                members = feats[labels == k]
                if members.shape[0]:
                    codewords[k] = np.median(members, axis=0)
                else:
                    codewords[k] = feats[int(dists.argmax())]
                    dists[int(dists.argmax())] = 0.0
            if prev - total <= tol * max(prev, 1e-9):
                break
            prev = total
        if codewords.shape[0] >= size or codewords.shape[0] >= feats.shape[0]:
            break
        n_split = min(codewords.shape[0], size - codewords.shape[0])
        jitter = rng.normal(0.0, 1.0, size=(n_split, feats.shape[1])).astype(np.float32)
        delta = epsilon * spread * (1.0 + 0.1 * jitter)
        split = codewords[:n_split]
        codewords = np.concatenate([split - delta, split + delta, codewords[n_split:]]).astype(
            np.float32
        )
    return codewords


def train_codebook(
    profiles: FloatArray,
    *,
    size: int = 32,
    seed: int = 0,
    quantile: float = 0.99,
    margin: float = 1.15,
    provenance: str = "",
) -> Codebook:
    """Rows by training deviation, LBG code words, threshold from training distortions.

    The threshold is `margin` times the `quantile` of the training silhouettes' own
    distortion to their nearest code word: it admits nearly every human seen in training
    with headroom for unseen poses, and the non-human tests measure what it rejects.
    """
    left_rows, right_rows = select_rows(profiles)
    feats = features_from_profiles(profiles, left_rows, right_rows)
    codewords = lbg_codebook(feats, size, seed=seed)
    _, dists = _assign(feats, codewords)
    threshold = float(np.quantile(dists, quantile)) * margin
    return Codebook(
        codewords=codewords,
        left_rows=left_rows,
        right_rows=right_rows,
        threshold=max(threshold, 1e-3),
        provenance=provenance,
    )
