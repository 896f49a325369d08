"""OpenCV's HOG people detector behind the `Detector` interface.

It needs no background model, so it works while the camera moves. The Dalal-Triggs people
weights ship inside OpenCV 4.x (`cv2.HOGDescriptor_getDefaultPeopleDetector`); OpenCV 5
moved HOG to the contrib module `xobjdetect`, which the 5.0 Python wheels do not build, so
on such a build `hog_available()` is False and `make_detector` raises `DetectorUnavailable`.
"""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np

from ptzd.vision.detect.config import HogConfig
from ptzd.vision.detect.types import Detection, Frame


class DetectorUnavailableError(RuntimeError):
    """The configured detector cannot run with the installed libraries."""

    def __init__(self, kind: str, reason: str) -> None:
        self.kind = kind
        self.reason = reason
        super().__init__(f"detector {kind!r} unavailable: {reason}")


def _hog_module() -> Any:
    for module in (cv2, getattr(cv2, "xobjdetect", None)):
        if module is not None and hasattr(module, "HOGDescriptor"):
            return module
    return None


def hog_available() -> bool:
    return _hog_module() is not None


class HogPeopleDetector:
    """HOG + linear SVM sliding window on a (by default) reduced-size frame."""

    name = "hog"

    def __init__(self, config: HogConfig) -> None:
        self._cfg = config
        self._hog: Any = None

    def _descriptor(self) -> Any:
        if self._hog is None:
            module = _hog_module()
            if module is None:
                raise DetectorUnavailableError(
                    "hog", f"OpenCV {cv2.__version__} has no HOGDescriptor (install OpenCV 4.x)"
                )
            hog = module.HOGDescriptor()
            people = (
                module.HOGDescriptor_getDefaultPeopleDetector()
                if hasattr(module, "HOGDescriptor_getDefaultPeopleDetector")
                else hog.getDefaultPeopleDetector()
            )
            hog.setSVMDetector(people)
            self._hog = hog
        return self._hog

    def reset(self) -> None:
        """Stateless: nothing to forget."""

    def detect(self, frame: Frame, *, camera_moving: bool = False) -> list[Detection]:
        cfg = self._cfg
        hog = self._descriptor()
        image: Any = frame
        if cfg.resize != 1.0:
            image = cv2.resize(
                frame, None, fx=cfg.resize, fy=cfg.resize, interpolation=cv2.INTER_AREA
            )
        rects, weights = hog.detectMultiScale(
            image,
            hitThreshold=cfg.hit_threshold,
            winStride=(cfg.win_stride, cfg.win_stride),
            padding=(8, 8),
            scale=cfg.scale_step,
        )
        out: list[Detection] = []
        inv = 1.0 / cfg.resize
        # Dalal-Triggs windows are 64x128 around a ~32x96 person (16 px margin on every side):
        # report the person's box, not the window's
        mx, my, sw, sh = 0.25, 0.125, 0.5, 0.75
        for (x, y, w, h), weight in zip(
            np.asarray(rects).reshape(-1, 4), np.ravel(weights), strict=True
        ):
            # SVM margin -> (0, 1): 0.5 at the decision boundary
            score = float(1.0 / (1.0 + np.exp(-float(weight))))
            if score >= cfg.min_score:
                out.append(
                    Detection(
                        (x + mx * w) * inv, (y + my * h) * inv, sw * w * inv, sh * h * inv, score
                    )
                )
        return out
