"""Tracking metrics (OTB conventions) and the loader of `ptzd track` output.

Ground-truth files are read by `ptzd.sim.groundtruth.load_ground_truth` (one format, one place).

Conventions (the benchmark and its docs rely on them):

- Boxes are `(x, y, w, h)` in pixels, `x, y` the top-left corner; the centre is
  `(x + w/2, y + h/2)`.
- A sequence is scored on the frames where ground truth exists (optionally only those in a
  `[start, end]` range, e.g. the range a tracker ran over). Frames without ground truth are
  skipped whatever the tracker said there.
- On a scored frame a null prediction (the tracker reported the target lost) or a missing
  one (the tracker wrote nothing for that frame) counts as IoU 0 and an infinite centre
  error: it fails every success threshold above 0 and every precision threshold, and it is
  a lost frame.
- Success curve (Wu, Lim, Yang, "Online Object Tracking: A Benchmark", CVPR 2013): for each
  IoU threshold t in 0, 0.05, ..., 1 the share of scored frames with IoU > t (strictly, so
  at t = 0 a prediction must overlap, at t = 1 nothing succeeds). AUC is the mean of the
  curve over those 21 thresholds.
- Precision at 20 px: the share of scored frames whose centre error is <= 20 px.
- Lost frames: the number of scored frames with a null or missing prediction.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import numpy.typing as npt

from ptzd.errors import PtzdError

Box = tuple[float, float, float, float]
FloatArray = npt.NDArray[np.float64]

# OTB's 21 overlap thresholds 0, 0.05, ..., 1 (rounded so 0.15 is 0.15, not 0.15000000000000002)
IOU_THRESHOLDS: FloatArray = np.round(np.linspace(0.0, 1.0, 21), 10)
PRECISION_RADIUS_PX = 20.0


class TrackOutputError(PtzdError):
    """A `ptzd track` output file that cannot be used; names the file and why."""

    def __init__(self, path: str, reason: str) -> None:
        self.path = path
        self.reason = reason
        super().__init__(f"{path}: {reason}")


# --- per-frame measures -------------------------------------------------------------------


def iou(a: Box | None, b: Box | None) -> float:
    """Intersection over union of two boxes; 0 when either is None or they do not overlap."""
    if a is None or b is None:
        return 0.0
    ax, ay, aw, ah = a
    bx, by, bw, bh = b
    iw = min(ax + aw, bx + bw) - max(ax, bx)
    ih = min(ay + ah, by + bh) - max(ay, by)
    if iw <= 0.0 or ih <= 0.0:
        return 0.0
    inter = iw * ih
    union = aw * ah + bw * bh - inter
    return inter / union if union > 0.0 else 0.0


def center_error(a: Box | None, b: Box | None) -> float:
    """Euclidean distance between the box centres in pixels; infinite when either is None."""
    if a is None or b is None:
        return math.inf
    return math.hypot(
        (a[0] + a[2] / 2.0) - (b[0] + b[2] / 2.0), (a[1] + a[3] / 2.0) - (b[1] + b[3] / 2.0)
    )


# --- per-sequence scores ------------------------------------------------------------------


@dataclass(frozen=True)
class SequenceScore:
    """Scores of one tracker on one sequence (see the module docstring for the conventions)."""

    frames: int  # scored frames: ground truth exists (within the range, if one was given)
    lost_frames: int  # scored frames with a null or missing prediction
    auc: float  # mean of `success` over IOU_THRESHOLDS
    precision_20: float  # share of scored frames with centre error <= 20 px
    success: tuple[float, ...] = field(repr=False)  # success rate per IOU_THRESHOLDS entry
    mean_iou: float = 0.0

    def to_json(self) -> dict[str, object]:
        return {
            "frames": self.frames,
            "lost_frames": self.lost_frames,
            "auc": self.auc,
            "precision_20": self.precision_20,
            "mean_iou": self.mean_iou,
            "success": list(self.success),
        }


def scored_frames(
    ground_truth: Mapping[int, Box], start: int | None = None, end: int | None = None
) -> list[int]:
    """The frames a sequence is scored on: ground truth exists and `start <= frame <= end`."""
    return sorted(
        f for f in ground_truth if (start is None or f >= start) and (end is None or f <= end)
    )


def per_frame(
    predictions: Mapping[int, Box | None],
    ground_truth: Mapping[int, Box],
    frames: list[int],
) -> tuple[FloatArray, FloatArray]:
    """IoU and centre error on each of `frames` (a missing prediction counts as null)."""
    ious = np.array([iou(predictions.get(f), ground_truth[f]) for f in frames], dtype=np.float64)
    errors = np.array(
        [center_error(predictions.get(f), ground_truth[f]) for f in frames], dtype=np.float64
    )
    return ious, errors


def success_curve(ious: FloatArray) -> FloatArray:
    """Share of frames with IoU strictly above each of IOU_THRESHOLDS (zeros if no frames)."""
    if ious.size == 0:
        return np.zeros_like(IOU_THRESHOLDS)
    return np.asarray((ious[None, :] > IOU_THRESHOLDS[:, None]).mean(axis=1), dtype=np.float64)


def precision_at(errors: FloatArray, radius: float = PRECISION_RADIUS_PX) -> float:
    """Share of frames with centre error <= `radius` pixels (0 if no frames)."""
    if errors.size == 0:
        return 0.0
    return float((errors <= radius).mean())


def score_sequence(
    predictions: Mapping[int, Box | None],
    ground_truth: Mapping[int, Box],
    start: int | None = None,
    end: int | None = None,
) -> SequenceScore:
    """Score `predictions` against `ground_truth` on the frames `scored_frames` picks."""
    frames = scored_frames(ground_truth, start, end)
    ious, errors = per_frame(predictions, ground_truth, frames)
    curve = success_curve(ious)
    lost = sum(1 for f in frames if predictions.get(f) is None)
    return SequenceScore(
        frames=len(frames),
        lost_frames=lost,
        auc=float(curve.mean()),
        precision_20=precision_at(errors),
        success=tuple(float(s) for s in curve),
        mean_iou=float(ious.mean()) if ious.size else 0.0,
    )


# --- files --------------------------------------------------------------------------------


def _read_json(path: Path) -> object:
    try:
        with open(path, encoding="utf-8") as fh:
            return json.load(fh)
    except OSError as exc:
        raise TrackOutputError(str(path), f"cannot read: {exc.strerror or exc}") from exc
    except json.JSONDecodeError as exc:
        raise TrackOutputError(str(path), f"not JSON: {exc}") from exc


def _parse_box(path: Path, where: str, value: object, *, allow_null: bool) -> Box | None:
    if value is None and allow_null:
        return None
    if (
        not isinstance(value, list)
        or len(value) != 4
        or not all(isinstance(v, int | float) and not isinstance(v, bool) for v in value)
    ):
        raise TrackOutputError(str(path), f"{where}: expected [x, y, w, h], got {value!r}")
    x, y, w, h = (float(v) for v in value)
    if not all(math.isfinite(v) for v in (x, y, w, h)) or w <= 0.0 or h <= 0.0:
        raise TrackOutputError(str(path), f"{where}: box needs finite values and w, h > 0")
    return (x, y, w, h)


def _parse_frames(
    path: Path, where: str, value: object, *, allow_null: bool
) -> dict[int, Box | None]:
    if not isinstance(value, dict):
        raise TrackOutputError(str(path), f"{where}: expected an object of frame -> box")
    out: dict[int, Box | None] = {}
    for key, box in value.items():
        try:
            frame = int(key)
        except ValueError:
            raise TrackOutputError(
                str(path), f"{where}: frame key {key!r} is not an integer"
            ) from None
        if frame < 0:
            raise TrackOutputError(str(path), f"{where}: frame index {frame} is negative")
        out[frame] = _parse_box(path, f"{where}[{key}]", box, allow_null=allow_null)
    return out


def load_track_output(path: str | Path) -> dict[int, Box | None]:
    """The boxes of a `ptzd track` output file, frame -> box or None (lost)."""
    path = Path(path)
    data = _read_json(path)
    if not isinstance(data, dict) or "boxes" not in data:
        raise TrackOutputError(str(path), 'expected an object with "boxes"')
    return _parse_frames(path, "boxes", data["boxes"], allow_null=True)
