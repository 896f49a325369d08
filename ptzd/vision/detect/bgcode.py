"""The seed-002 detector: background subtraction, connected components, codebook matching."""

from __future__ import annotations

from dataclasses import dataclass
from typing import cast

import cv2
import numpy as np
from numpy.typing import NDArray

from ptzd.vision.detect.background import U8, ForegroundMasks, RunningAverageBackground, to_grey
from ptzd.vision.detect.codebook import Codebook
from ptzd.vision.detect.config import BgCodeConfig
from ptzd.vision.detect.shape import FEATURE_DIM, normalise_silhouette, shape_feature
from ptzd.vision.detect.types import Detection, Frame


@dataclass(frozen=True)
class Candidate:
    """A moving region: tight box of its thresholded pixels and its dilated silhouette."""

    x: int
    y: int
    w: int
    h: int
    silhouette: NDArray[np.bool_]


def is_ghost(cand: Candidate, grey: U8, background: U8, *, ratio: float = 0.8) -> bool:
    """True when the region's outline is an edge of the background, not of the frame.

    A real object has its outline in the current frame; a ghost (where something stood
    when the model started) shows the old object's outline in the background image and
    none in the frame. Compares the mean gradient magnitude along the region's boundary.
    """
    pad = 2
    h_img, w_img = grey.shape
    x0, y0 = max(0, cand.x - pad), max(0, cand.y - pad)
    x1, y1 = min(w_img, cand.x + cand.w + pad), min(h_img, cand.y + cand.h + pad)
    region = np.zeros((y1 - y0, x1 - x0), dtype=np.uint8)
    oy, ox = cand.y - y0, cand.x - x0
    region[oy : oy + cand.h, ox : ox + cand.w] = cand.silhouette.astype(np.uint8) * 255
    outline = cv2.morphologyEx(region, cv2.MORPH_GRADIENT, _OUTLINE_KERNEL) > 0
    if not outline.any():
        return False
    now = _gradient(grey[y0:y1, x0:x1])[outline].mean()
    before = _gradient(background[y0:y1, x0:x1])[outline].mean()
    return bool(now < ratio * before)


_OUTLINE_KERNEL = cv2.getStructuringElement(cv2.MORPH_RECT, (3, 3))


def _gradient(patch: U8) -> NDArray[np.float32]:
    gx = cv2.Sobel(patch, cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(patch, cv2.CV_32F, 0, 1, ksize=3)
    return cast(NDArray[np.float32], cv2.magnitude(gx, gy))


def touches_border(cand: Candidate, size: tuple[int, int], margin: int = 1) -> bool:
    w, h = size
    return (
        cand.x < margin
        or cand.y < margin
        or cand.x + cand.w > w - margin
        or cand.y + cand.h > h - margin
    )


def candidate_regions(masks: ForegroundMasks, min_area: int) -> list[Candidate]:
    """Connected regions of the dilated mask with at least `min_area` pixels.

    Regions are the filled outer contours of the dilated mask (the seed's dilation is there
    to fill holes; contour tracing costs a fraction of a labelling pass here). The box is
    that of the region's un-dilated pixels, so dilation does not inflate it; the silhouette
    is the filled region inside that box.
    """
    contours, _ = cv2.findContours(masks.dilated, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    out: list[Candidate] = []
    for contour in contours:
        x0, y0, w0, h0 = cv2.boundingRect(contour)
        if w0 * h0 < min_area:
            continue
        region = np.zeros((h0, w0), dtype=np.uint8)
        cv2.drawContours(region, [contour], -1, 255, thickness=cv2.FILLED, offset=(-x0, -y0))
        if cv2.countNonZero(region) < min_area:
            continue
        raw = cv2.bitwise_and(region, masks.raw[y0 : y0 + h0, x0 : x0 + w0])
        if not cv2.countNonZero(raw):
            continue
        rx, ry, rw, rh = cv2.boundingRect(raw)
        silhouette = region[ry : ry + rh, rx : rx + rw] > 0
        out.append(Candidate(x0 + rx, y0 + ry, rw, rh, silhouette))
    return out


class BackgroundCodebookDetector:
    """Seed-002 human detection; runs only while the camera is still.

    `detect(frame, camera_moving=True)` learns nothing and returns nothing; the first still
    frame after a move starts a new background, and detections resume after warm-up.
    """

    name = "bgcode"

    def __init__(self, config: BgCodeConfig, codebook: Codebook) -> None:
        self._cfg = config
        self.codebook = codebook
        self.threshold = (
            config.distortion_threshold
            if config.distortion_threshold is not None
            else codebook.threshold
        )
        self.model = RunningAverageBackground(config)
        self._was_moving = False
        self.ghosts_absorbed = 0

    def reset(self) -> None:
        self.model.reset()

    def classify(self, candidates: list[Candidate]) -> list[tuple[Candidate, float]]:
        """Candidates with an admissible aspect ratio, each with its distortion (eq. 5)."""
        cfg = self._cfg
        kept = [
            c
            for c in candidates
            if c.h >= cfg.min_height
            and cfg.aspect_min <= c.h / c.w <= cfg.aspect_max
            and float(c.silhouette.mean()) <= cfg.max_fill
        ]
        if not kept:
            return []
        feats = np.empty((len(kept), FEATURE_DIM), dtype=np.float32)
        for i, cand in enumerate(kept):
            norm = normalise_silhouette(cand.silhouette)
            feats[i] = shape_feature(norm, self.codebook.left_rows, self.codebook.right_rows)
        dists = self.codebook.distortion(feats)
        return [(c, float(d)) for c, d in zip(kept, dists, strict=True)]

    def detect(self, frame: Frame, *, camera_moving: bool = False) -> list[Detection]:
        if camera_moving:
            self._was_moving = True
            return []
        if self._was_moving:
            self._was_moving = False
            self.model.reset()
        grey = to_grey(frame)
        masks = self.model.apply(grey)
        background = self.model.background
        if masks is None or background is None:
            return []
        size = (grey.shape[1], grey.shape[0])
        candidates = []
        for cand in candidate_regions(masks, self._cfg.min_area):
            if self._cfg.reject_border and touches_border(cand, size):
                continue
            if is_ghost(cand, grey, background):
                self.model.absorb(cand.x, cand.y, cand.silhouette, grey)
                self.ghosts_absorbed += 1
                continue
            candidates.append(cand)
        out: list[Detection] = []
        for cand, dist in self.classify(candidates):
            if dist < self.threshold:
                score = float(np.clip(1.0 - 0.5 * dist / self.threshold, 0.0, 1.0))
                out.append(Detection(cand.x, cand.y, cand.w, cand.h, score))
        return out
