"""Ground-truth files: where every tracked person is in every wide frame.

Format (shared/interfaces.md; checks outside the project read it, keep it exactly)::

    {"size": [W, H], "fps": F,
     "tracks": [{"id": N, "frames": {"<frame index>": [x, y, w, h], ...}}, ...]}

Boxes are in wide-frame pixels; frame 0 is the first frame cv2.VideoCapture reads. A box
`[x, y, w, h]` covers pixel columns x .. x+w-1 and rows y .. y+h-1 (cv2.boundingRect's
convention). A track may carry an optional extra map `"visibility": {"<frame index>": v}`
(0..1, the fraction of the body's pixels that are visible); readers that do not know it
ignore it, and `load_ground_truth` ignores any other unknown key too.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

from ptzd.errors import UsageError

Box = tuple[float, float, float, float]
T = TypeVar("T")


class GroundTruthError(UsageError):
    """A ground-truth file that cannot be read, is malformed, or does not fit its video.

    `path` is the file, `where` the JSON location of the problem (empty for the whole file).
    """

    def __init__(self, path: str, reason: str, where: str = "") -> None:
        self.path = path
        self.reason = reason
        self.where = where
        location = f" at {where}" if where else ""
        super().__init__(f"ground truth {path}{location}: {reason}")


@dataclass(frozen=True)
class GroundTruth:
    """Per-frame boxes of every track; `visibility` (optional) per track and frame, 0..1."""

    size: tuple[int, int]  # (W, H) of the wide frames
    fps: float
    tracks: dict[int, dict[int, Box]]
    visibility: dict[int, dict[int, float]] = field(default_factory=dict)

    def boxes_at(self, frame: int) -> dict[int, Box]:
        """`{track id: box}` of every track present in `frame`."""
        return {tid: frames[frame] for tid, frames in self.tracks.items() if frame in frames}


def save_ground_truth(gt: GroundTruth, path: str | Path) -> None:
    """Write `gt` in the shared format (frames in ascending order; visibility if known)."""
    tracks: list[dict[str, Any]] = []
    for track_id in sorted(gt.tracks):
        frames = gt.tracks[track_id]
        entry: dict[str, Any] = {
            "id": track_id,
            "frames": {str(i): [_number(v) for v in frames[i]] for i in sorted(frames)},
        }
        visible = gt.visibility.get(track_id)
        if visible:
            entry["visibility"] = {str(i): round(visible[i], 4) for i in sorted(visible)}
        tracks.append(entry)
    doc = {"size": [gt.size[0], gt.size[1]], "fps": gt.fps, "tracks": tracks}
    Path(path).write_text(json.dumps(doc, separators=(",", ":")) + "\n", encoding="utf-8")


def _number(value: float) -> float | int:
    """Integral coordinates as JSON integers (smaller files, and exactly what was drawn)."""
    return int(value) if float(value).is_integer() else round(float(value), 3)


def load_ground_truth(
    path: str | Path, *, expected_size: tuple[int, int] | None = None
) -> GroundTruth:
    """Read and validate a ground-truth file; `expected_size` is the video's (W, H).

    Raises `GroundTruthError` naming the file and the offending JSON location.
    """
    name = str(path)
    try:
        text = Path(path).read_text(encoding="utf-8")
    except OSError as exc:
        raise GroundTruthError(name, f"cannot read: {exc.strerror or exc}") from None
    except UnicodeDecodeError:
        raise GroundTruthError(name, "not UTF-8 text") from None
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise GroundTruthError(name, f"not JSON ({exc.msg}, line {exc.lineno})") from None
    gt = _parse(name, doc)
    if expected_size is not None and gt.size != tuple(expected_size):
        raise GroundTruthError(
            name,
            f"made for {gt.size[0]}x{gt.size[1]} frames but the video is "
            f"{expected_size[0]}x{expected_size[1]}",
            "size",
        )
    return gt


def _parse(name: str, doc: object) -> GroundTruth:
    if not isinstance(doc, Mapping):
        raise GroundTruthError(name, "expected a JSON object with size, fps and tracks")
    for key in ("size", "fps", "tracks"):
        if key not in doc:
            raise GroundTruthError(name, f"missing key {key!r}")
    size = doc["size"]
    if (
        not isinstance(size, list)
        or len(size) != 2
        or not all(isinstance(v, int) and not isinstance(v, bool) and v > 0 for v in size)
    ):
        raise GroundTruthError(
            name, f"expected [W, H] with positive integers, got {size!r}", "size"
        )
    fps = doc["fps"]
    if not _is_number(fps) or not 0.0 < float(fps) < 10000.0:
        raise GroundTruthError(name, f"expected a positive number, got {fps!r}", "fps")
    raw_tracks = doc["tracks"]
    if not isinstance(raw_tracks, list):
        raise GroundTruthError(name, "expected a list of tracks", "tracks")
    tracks: dict[int, dict[int, Box]] = {}
    visibility: dict[int, dict[int, float]] = {}
    for n, track in enumerate(raw_tracks):
        where = f"tracks[{n}]"
        if not isinstance(track, Mapping) or "id" not in track or "frames" not in track:
            raise GroundTruthError(name, "expected an object with id and frames", where)
        track_id = track["id"]
        if not isinstance(track_id, int) or isinstance(track_id, bool):
            raise GroundTruthError(name, f"id must be an integer, got {track_id!r}", where)
        if track_id in tracks:
            raise GroundTruthError(name, f"duplicate track id {track_id}", where)
        tracks[track_id] = _parse_map(name, track["frames"], f"{where}.frames", _box)
        if "visibility" in track:
            visibility[track_id] = _parse_map(
                name, track["visibility"], f"{where}.visibility", _fraction
            )
    return GroundTruth((size[0], size[1]), float(fps), tracks, visibility)


def _parse_map(
    name: str, raw: object, where: str, parse_value: Callable[[object], T | None]
) -> dict[int, T]:
    if not isinstance(raw, Mapping):
        raise GroundTruthError(name, 'expected an object {"<frame index>": ...}', where)
    out: dict[int, T] = {}
    for key, value in raw.items():
        if not isinstance(key, str) or not key.isdigit():
            raise GroundTruthError(
                name, f"frame index must be a non-negative integer, got {key!r}", where
            )
        parsed = parse_value(value)
        if parsed is None:
            raise GroundTruthError(name, f"bad value {value!r}", f'{where}["{key}"]')
        out[int(key)] = parsed
    return out


def _is_number(value: object) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def _box(value: object) -> Box | None:
    """[x, y, w, h] with finite numbers and w, h >= 0, else None."""
    if not isinstance(value, list) or len(value) != 4 or not all(_is_number(v) for v in value):
        return None
    x, y, w, h = (float(v) for v in value)
    if w < 0 or h < 0:
        return None
    return (x, y, w, h)


def _fraction(value: object) -> float | None:
    if not isinstance(value, int | float) or not _is_number(value):
        return None
    return float(value) if 0.0 <= value <= 1.0 else None
