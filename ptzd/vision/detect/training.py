"""Silhouettes for codebook training, cut out the same way the detector cuts them.

Every labelled sequence (a simulator scene, a procedural `FigureScene`, or a video with a
ground-truth file) is run through the detector's own background model; for each
ground-truth box that is fully inside the frame and overlaps no other person, the moving
region that best matches the box (IoU >= `min_iou`) gives one silhouette. Training on the
detector's own masks means the code words carry its dilation, noise and shadows.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np

from ptzd.vision.detect.background import RunningAverageBackground, to_grey
from ptzd.vision.detect.bgcode import candidate_regions
from ptzd.vision.detect.config import BgCodeConfig
from ptzd.vision.detect.shape import FloatArray, full_profile, normalise_silhouette
from ptzd.vision.detect.types import Box, Frame, iou

MIN_VISIBILITY = 0.9
"""People less visible than this (when the truth says) give no training silhouette."""


class TrainingSourceError(ValueError):
    """A training source that cannot be opened or parsed; carries the source string."""

    def __init__(self, source: str, reason: str) -> None:
        self.source = source
        self.reason = reason
        super().__init__(f"training source {source!r}: {reason}")


@dataclass(frozen=True)
class LabelledSequence:
    """Frames (read in order) and the ground-truth boxes of each frame index."""

    name: str
    size: tuple[int, int]
    frame_count: int
    read: Callable[[int], Frame]
    boxes: Callable[[int], list[Box]]
    hidden: Callable[[int], list[Box]] = lambda _i: []
    """Boxes of people the truth says are partly hidden (not used as training silhouettes)."""


def boxes_by_frame(tracks: Mapping[int, Mapping[int, Box]]) -> dict[int, list[Box]]:
    """Invert `{track: {frame: box}}` into `{frame: [box, ...]}`."""
    out: dict[int, list[Box]] = {}
    for frames in tracks.values():
        for frame, box in frames.items():
            out.setdefault(int(frame), []).append(tuple(float(v) for v in box))  # type: ignore[arg-type]
    return out


def _inside(box: Box, size: tuple[int, int], margin: float = 2.0) -> bool:
    x, y, w, h = box
    return x >= margin and y >= margin and x + w <= size[0] - margin and y + h <= size[1] - margin


def isolated_boxes(boxes: list[Box], size: tuple[int, int]) -> list[Box]:
    """Boxes fully in view that touch no other box (their silhouettes are unambiguous)."""
    out = []
    for i, box in enumerate(boxes):
        if not _inside(box, size):
            continue
        if any(iou(_grow(box, 4.0), other) > 0 for j, other in enumerate(boxes) if j != i):
            continue
        out.append(box)
    return out


def _grow(box: Box, by: float) -> Box:
    x, y, w, h = box
    return (x - by, y - by, w + 2 * by, h + 2 * by)


def sequence_profiles(
    seq: LabelledSequence,
    config: BgCodeConfig,
    *,
    min_iou: float = 0.6,
    min_height: int = 36,
    stride: int = 1,
    max_frames: int | None = None,
) -> FloatArray:
    """(N, 90) full profiles of the isolated walkers' silhouettes in `seq`.

    Silhouettes shorter than `min_height` are left out: normalised to 20x40 they are filled
    boxes, and code words made of them would match any box-shaped blob.
    """
    model = RunningAverageBackground(config)
    profiles: list[FloatArray] = []
    last = seq.frame_count if max_frames is None else min(seq.frame_count, max_frames)
    for i in range(last):
        masks = model.apply(to_grey(seq.read(i)))
        if masks is None or i % stride:
            continue
        hidden = seq.hidden(i)
        targets = [b for b in isolated_boxes(seq.boxes(i), seq.size) if b not in hidden]
        if not targets:
            continue
        cands = candidate_regions(masks, config.min_area)
        for box in targets:
            scored = [(iou(box, (c.x, c.y, c.w, c.h)), c) for c in cands]
            if not scored:
                continue
            best_iou, best = max(scored, key=lambda s: s[0])
            if best_iou >= min_iou and best.h >= min_height:
                profiles.append(full_profile(normalise_silhouette(best.silhouette)))
    if not profiles:
        return np.zeros((0, 90), dtype=np.float32)
    return np.stack(profiles).astype(np.float32)


def open_training_source(
    source: str, *, gt: str | None = None, scene_size: tuple[int, int] | None = None
) -> LabelledSequence:
    """`synthetic[:SEED]` (the simulator's scene), `figures:SEED` (procedural walkers), or a
    video file with its ground-truth file `gt` (shared/interfaces.md format).

    `scene_size` renders simulator scenes at that (W, H) instead of their default size."""
    if source.startswith("figures:"):
        from ptzd.vision.detect.figures import FigureScene

        scene = FigureScene(_seed(source), frame_count=300, walkers=4)
        return LabelledSequence(
            name=source,
            size=scene.size,
            frame_count=scene.frame_count,
            read=scene.read,
            boxes=scene.float_boxes,
        )
    from ptzd.sim.sources import WideSource, open_wide_source

    is_scene = source.partition(":")[0] in ("synthetic", "synthetic-thermal")
    if not is_scene and gt is None:
        raise TrainingSourceError(source, "a video needs its ground-truth file (--gt)")
    wide: WideSource
    if is_scene and scene_size is not None:
        from ptzd.sim.scene import SceneParams, SceneSource

        kind, _, arg = source.partition(":")
        params = SceneParams(width=scene_size[0], height=scene_size[1])
        wide = SceneSource(
            _seed(source) if arg else 0, thermal=kind == "synthetic-thermal", params=params
        )
    else:
        wide = open_wide_source(source, gt_path=gt)
    truth = wide.ground_truth
    if truth is None:
        raise TrainingSourceError(source, "the source has no ground truth")
    count = wide.frame_count
    if count is None:
        raise TrainingSourceError(source, "the source is endless; training needs a frame count")
    by_frame = boxes_by_frame(truth.tracks)
    hidden: dict[int, list[Box]] = {}
    for track_id, seen in truth.visibility.items():
        for frame, fraction in seen.items():
            if fraction < MIN_VISIBILITY and frame in truth.tracks.get(track_id, {}):
                hidden.setdefault(frame, []).append(truth.tracks[track_id][frame])
    return LabelledSequence(
        name=source,
        size=(int(wide.size[0]), int(wide.size[1])),
        frame_count=int(count),
        read=wide.read,
        boxes=lambda i: by_frame.get(i, []),
        hidden=lambda i: hidden.get(i, []),
    )


def _seed(source: str) -> int:
    try:
        return int(source.split(":", 1)[1])
    except (IndexError, ValueError):
        raise TrainingSourceError(source, "expected KIND:SEED with an integer seed") from None
