"""Detection scoring against ground truth: recall and precision at an IoU threshold.

Protocol (used by bench/detect.py and the tests): a ground-truth person *counts* in a frame
when its box is fully inside the view and touches no other person's box; people cut by the
frame edge, merged with another person or (when the truth says so) less than 90 % visible
are *don't care*: missing them costs nothing and a
detection matching them (IoU >= threshold) is neither a hit nor a false alarm. Every other
detection is a false positive. Matching is greedy by IoU, one detection per person.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

from ptzd.vision.detect.training import isolated_boxes
from ptzd.vision.detect.types import Box, iou


@dataclass
class DetectionScore:
    true_positives: int = 0
    false_positives: int = 0
    false_negatives: int = 0
    frames: int = 0
    missed: list[tuple[int, Box]] = field(default_factory=list)
    false_alarms: list[tuple[int, Box]] = field(default_factory=list)

    @property
    def recall(self) -> float:
        n = self.true_positives + self.false_negatives
        return self.true_positives / n if n else 1.0

    @property
    def precision(self) -> float:
        n = self.true_positives + self.false_positives
        return self.true_positives / n if n else 1.0

    def add_frame(
        self,
        index: int,
        detections: Sequence[Box],
        truth: Sequence[Box],
        size: tuple[int, int],
        *,
        visibility: Sequence[float] | None = None,
        min_visibility: float = 0.9,
        min_iou: float = 0.5,
    ) -> None:
        """Score one frame; `visibility` (per truth box, 0..1) marks occluded people don't care."""
        self.frames += 1
        counted = isolated_boxes(list(truth), size)
        if visibility is not None:
            seen = [b for b, v in zip(truth, visibility, strict=True) if v >= min_visibility]
            counted = [b for b in counted if b in seen]
        ignored = [b for b in truth if b not in counted]
        pairs = sorted(
            (
                (iou(d, g), di, gi)
                for di, d in enumerate(detections)
                for gi, g in enumerate(counted)
            ),
            reverse=True,
        )
        used_d: set[int] = set()
        used_g: set[int] = set()
        for overlap, di, gi in pairs:
            if overlap < min_iou:
                break
            if di in used_d or gi in used_g:
                continue
            used_d.add(di)
            used_g.add(gi)
        self.true_positives += len(used_g)
        for gi, g in enumerate(counted):
            if gi not in used_g:
                self.false_negatives += 1
                self.missed.append((index, g))
        for di, d in enumerate(detections):
            if di in used_d:
                continue
            # overlapping a don't-care person (partly visible or merged): not a false alarm
            if any(iou(d, g) > 0.1 for g in ignored) or any(iou(d, g) >= min_iou for g in counted):
                continue
            self.false_positives += 1
            self.false_alarms.append((index, d))
