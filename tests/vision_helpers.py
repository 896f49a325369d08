"""Synthetic scenes with exact ground truth for the tracker tests.

A smooth random background, a two-colour "pedestrian" (red top, blue bottom) moving at
constant velocity, optional distractor and occluder. Deterministic for a seed.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from ptzd.metrics import Box as Box
from ptzd.metrics import iou as iou
from ptzd.vision.config import TrackerConfig
from ptzd.vision.tracking import TrackState, make_tracker

Frame = NDArray[np.uint8]


@functools.lru_cache(maxsize=8)
def background(width: int, height: int, seed: int) -> Frame:
    rng = np.random.default_rng(seed)
    small = rng.integers(60, 200, (height // 16 + 1, width // 16 + 1, 3), dtype=np.uint8)
    # greenish-grey, low saturation, like grass and pavement
    small[..., 1] = np.clip(small[..., 1].astype(int) + 20, 0, 255).astype(np.uint8)
    big = cv2.resize(small, (width, height), interpolation=cv2.INTER_CUBIC)
    noise = rng.integers(-8, 9, big.shape)
    out = np.clip(big.astype(int) + noise, 0, 255).astype(np.uint8)
    out.flags.writeable = False  # cached: callers copy before drawing
    return out


def draw_person(
    frame: Frame, box: Box, top: tuple[int, int, int], bottom: tuple[int, int, int]
) -> None:
    x, y, w, h = (round(v) for v in box)
    cv2.rectangle(frame, (x, y), (x + w - 1, y + h // 2 - 1), top, -1)
    cv2.rectangle(frame, (x, y + h // 2), (x + w - 1, y + h - 1), bottom, -1)
    cv2.circle(frame, (x + w // 2, y + h // 5), max(w // 5, 2), (90, 140, 200), -1)


@dataclass
class Scene:
    width: int = 320
    height: int = 240
    seed: int = 0
    start: Box = (60.0, 80.0, 24.0, 60.0)
    velocity: tuple[float, float] = (2.0, 0.5)
    growth: float = 0.0  # relative size change per frame
    occluder_x: tuple[int, int] | None = None  # columns of a full-height grey bar in front
    vanish_after: int | None = None  # target leaves the scene after this frame
    shift: tuple[float, float] = (0.0, 0.0)  # whole-image shift per frame (camera pan)

    def truth(self, t: int) -> Box:
        x, y, w, h = self.start
        s = (1.0 + self.growth) ** t
        cx = x + w / 2 + self.velocity[0] * t + self.shift[0] * t
        cy = y + h / 2 + self.velocity[1] * t + self.shift[1] * t
        return (cx - w * s / 2, cy - h * s / 2, w * s, h * s)

    def frame(self, t: int) -> Frame:
        bg = background(self.width + 400, self.height + 400, self.seed)
        ox = 200 - round(self.shift[0] * t)
        oy = 200 - round(self.shift[1] * t)
        img = bg[oy : oy + self.height, ox : ox + self.width].copy()
        if self.vanish_after is None or t <= self.vanish_after:
            draw_person(img, self.truth(t), (40, 40, 200), (160, 60, 20))
        if self.occluder_x is not None:
            x0, x1 = self.occluder_x
            img[:, x0:x1] = (128, 128, 128)
        return img


def vanishing_walker(shift: tuple[float, float]) -> tuple[Scene, NDArray[np.float64] | None]:
    """A walker stepping 8 px a frame who vanishes after frame 15 (the truth walks on), seen
    by a camera panning `shift` px a frame; and the ego-motion to hand a tracker (None when
    the camera is still). The coast must move with the image as well as with him."""
    scene = Scene(velocity=(8.0, 0.0), start=(20.0, 90.0, 24.0, 60.0), vanish_after=15, shift=shift)
    return scene, np.array(shift) if shift != (0.0, 0.0) else None


def twin_scene(velocity: float, frames: int) -> tuple[Scene, list[Frame]]:
    """A walker leaving behind a still twin (a figure in his colours where he started)."""
    scene = Scene(velocity=(velocity, 0.0))
    out = []
    for t in range(frames):
        frame = scene.frame(t)
        draw_person(frame, scene.start, (40, 40, 200), (160, 60, 20))
        out.append(frame)
    return scene, out


def twin_outcomes(
    velocity: float, frames: int, kind: str, variants: dict[str, dict[str, Any]], seeds: int
) -> dict[str, list[tuple[TrackState, float, float]]]:
    """Per variant (`kind`'s own config section) and tracker seed, how the tracker ends on a
    `twin_scene`: its state and its box's IoU with the walker's last box and with the twin."""
    scene, images = twin_scene(velocity, frames)
    end = scene.truth(frames - 1)
    outcome: dict[str, list[tuple[TrackState, float, float]]] = {}
    for name, section in variants.items():
        outcome[name] = []
        for seed in range(seeds):
            tracker = make_tracker(
                TrackerConfig.model_validate({"kind": kind, "seed": seed, kind: section})
            )
            tracker.init(images[0], scene.truth(0))
            for image in images[1:]:
                result = tracker.update(image)
            outcome[name].append((result.state, iou(result.box, end), iou(result.box, scene.start)))
    return outcome


def synthetic_window(seed: int, first: int, count: int) -> tuple[Any, list[Frame]]:
    """`synthetic:SEED`'s ground truth and its scene frames first..first+count-1."""
    from ptzd.sim.sources import open_wide_source

    source = open_wide_source(f"synthetic:{seed}")
    assert source.ground_truth is not None
    return source.ground_truth, [source.read(i) for i in range(first, first + count)]
