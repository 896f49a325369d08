"""Running-average background subtraction of seed 002 (Chang et al. 2020, eqs. 1-3).

Eq. 1 updates the background B <- alpha*B + (1-alpha)*I except at active pixels I_M,
eq. 2-3 threshold |I - B| into the moving-object mask, which is then dilated. The seed's
I_M is the set of pixels active between frames n-1 and n (temporal difference). Beyond the
seed, after warm-up I_M also holds the dilated foreground, so the uniform interior of a
walking person (no temporal change while it overlaps itself) is not averaged into the
background; such pixels are still updated, but at the slow `absorb_alpha`, and once a pixel
has been foreground without temporal change for `static_frames` it is updated at `alpha`,
so a parked car or the ghost of someone present at reset fades away instead of staying
foreground for ever. A global change (lights switched, exposure jump) that turns more than
`max_foreground_fraction` of the frame into foreground rebuilds the model from that frame.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import cast

import cv2
import numpy as np
from numpy.typing import NDArray

from ptzd.logs import get_logger
from ptzd.vision.detect.config import BgCodeConfig

U8 = NDArray[np.uint8]

_log = get_logger("detect")


def to_grey(frame: NDArray[np.uint8]) -> U8:
    """8-bit grey image of a BGR or grey frame."""
    if frame.ndim == 2:
        return frame
    if frame.ndim == 3 and frame.shape[2] == 3:
        return cast(U8, cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY))
    raise ValueError(f"expected an (H, W) or (H, W, 3) uint8 frame, got shape {frame.shape}")


@dataclass(frozen=True)
class ForegroundMasks:
    """The thresholded difference (eq. 3) and its dilation, both 0/255 uint8."""

    raw: U8
    dilated: U8


class RunningAverageBackground:
    """Per-pixel running-average background of grey frames; one instance per still view."""

    def __init__(self, config: BgCodeConfig) -> None:
        self._cfg = config
        size = 2 * config.dilate_px + 1
        self._kernel: U8 | None = (
            cast(U8, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (size, size)))
            if config.dilate_px
            else None
        )
        self._background: NDArray[np.float32] | None = None
        self._previous: U8 | None = None
        self._static: NDArray[np.uint16] | None = None
        self._frames = 0
        self.rebuilds = 0

    @property
    def frames_since_reset(self) -> int:
        return self._frames

    @property
    def ready(self) -> bool:
        """True once `warmup_frames` frames have been learnt since the last reset."""
        return self._frames >= self._cfg.warmup_frames

    @property
    def background(self) -> U8 | None:
        """The current background image (for overlays and tests), or None before a frame."""
        if self._background is None:
            return None
        return cast(U8, cv2.convertScaleAbs(self._background))

    def absorb(self, x: int, y: int, region: NDArray[np.bool_], grey: U8) -> None:
        """Copy `grey` into the background where `region` (placed at x, y) is set.

        For regions judged to be background (a ghost left by someone present at reset).
        """
        if self._background is None:
            return
        h, w = region.shape
        patch = self._background[y : y + h, x : x + w]
        patch[region] = grey[y : y + h, x : x + w][region]

    def reset(self) -> None:
        """Forget the background: the next frame starts a new model."""
        self._background = None
        self._previous = None
        self._static = None
        self._frames = 0

    def _dilate(self, mask: U8) -> U8:
        if self._kernel is None:
            return mask
        return cast(U8, cv2.dilate(mask, self._kernel))

    def _start(self, grey: U8) -> None:
        self._background = grey.astype(np.float32)
        self._previous = grey
        self._static = np.zeros(grey.shape, dtype=np.uint16)
        self._frames = 1

    def apply(self, grey: U8) -> ForegroundMasks | None:
        """Learn `grey` and return its foreground masks, or None while warming up."""
        cfg = self._cfg
        bg, prev, static = self._background, self._previous, self._static
        if bg is None or prev is None or static is None or bg.shape != grey.shape:
            self._start(grey)
            return None
        # eqs. 2-3: |I_c - I_B| >= ths
        diff = cv2.absdiff(grey, cv2.convertScaleAbs(bg))
        raw = cast(U8, cv2.threshold(diff, cfg.threshold - 1, 255, cv2.THRESH_BINARY)[1])
        if cv2.countNonZero(raw) > cfg.max_foreground_fraction * raw.size:
            _log.info(
                "background_rebuilt",
                reason="global_change",
                foreground_fraction=round(cv2.countNonZero(raw) / raw.size, 3),
            )
            self.rebuilds += 1
            self._start(grey)
            return None
        dilated = self._dilate(raw)
        # I_M: pixels active between frames n-1 and n
        temporal = cv2.absdiff(grey, prev)
        active = cast(U8, cv2.threshold(temporal, cfg.threshold - 1, 255, cv2.THRESH_BINARY)[1])
        active = self._dilate(active)
        warm = self._frames >= cfg.warmup_frames
        if warm:
            # foreground that has stayed put for static_frames is let into the background
            np.add(static, 1, out=static, where=static < np.iinfo(np.uint16).max)
            static[(active > 0) | (dilated == 0)] = 0
            moving_fg = dilated.copy()
            moving_fg[static >= cfg.static_frames] = 0
            hold = cv2.bitwise_or(active, moving_fg)
        else:
            hold = active
        # eq. 1: alpha*B + (1-alpha)*I outside I_M, B kept (here: slow absorb) inside I_M
        cv2.accumulateWeighted(grey, bg, 1.0 - cfg.alpha, mask=cv2.bitwise_not(hold))
        if cfg.absorb_alpha < 1.0:
            cv2.accumulateWeighted(grey, bg, 1.0 - cfg.absorb_alpha, mask=hold)
        self._previous = grey
        self._frames += 1
        if not warm:
            return None
        return ForegroundMasks(raw=raw, dilated=dilated)
