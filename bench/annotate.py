"""Semi-automatic pedestrian annotation for a static-camera video (how bench/annotations were made).

The camera is static, so a median background and a per-pixel colour difference give clean
silhouettes. A track is built from a spec file (bench/annotations/specs/*.spec.json):

    {"video": "data/vtest.avi", "id": 1, "start": 40, "end": 200,
     "keys": {"40": [x, y, w, h], ...},      # boxes set by hand after looking at the frames
     "interpolate": [[a, b], ...]}           # between keys a and b: linear interpolation

Frame by frame the box follows the foreground silhouette (the union of foreground components
overlapping the predicted box); a key frame overrides it and restarts the follower from the
hand-set box; inside an `interpolate` range the box is the linear interpolation of the two
keys (used only where the motion is smooth, e.g. behind the lamp post or while two people
overlap). Frames where the follower is unsure (no foreground, or a silhouette much larger
than the target because it merged with someone) are reported so a key can be placed there.

Commands (run with the project venv):
    python -m bench.annotate blobs --frame N --out /tmp/blobs.png     # pick an init box
    python -m bench.annotate build SPEC... --out-dir bench/annotations
    python -m bench.annotate review GT.json --track ID [--start A --end B --every K] --out PNG

`review` draws the boxes on crops (green: followed, blue: key, yellow: interpolated, red:
unsure) so every box can be checked by eye; fixes go into the spec as keys.
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import numpy.typing as npt

from ptzd.metrics import Box
from ptzd.sim.groundtruth import GroundTruth, load_ground_truth, save_ground_truth

Image = npt.NDArray[np.uint8]

# foreground: max channel difference to the median background above this (0..255)
DIFF_THRESHOLD = 30
MIN_COMPONENT_AREA = 20
# a followed silhouette this much wider / taller than the target merged with something else
MAX_GROWTH_W = 1.45
MAX_GROWTH_H = 1.3


def read_video(path: str | Path) -> list[Image]:
    cap = cv2.VideoCapture(str(path))
    if not cap.isOpened():
        raise SystemExit(f"cannot open video {path}")
    frames: list[Image] = []
    while True:
        ok, frame = cap.read()
        if not ok:
            break
        frames.append(np.asarray(frame, dtype=np.uint8))
    cap.release()
    if not frames:
        raise SystemExit(f"no frames decoded from {path}")
    return frames


def median_background(frames: list[Image], step: int = 5) -> Image:
    background: Image = np.median(np.stack(frames[::step]), axis=0).astype(np.uint8)
    return background


def foreground(frame: Image, background: Image) -> Image:
    diff = np.abs(frame.astype(np.int16) - background.astype(np.int16)).max(axis=2)
    mask = (diff > DIFF_THRESHOLD).astype(np.uint8) * 255
    mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, np.ones((3, 3), np.uint8))
    return np.asarray(cv2.morphologyEx(mask, cv2.MORPH_CLOSE, np.ones((7, 5), np.uint8)))


def components(mask: Image) -> list[tuple[int, int, int, int]]:
    _, _, stats, _ = cv2.connectedComponentsWithStats(mask)
    return [
        (int(s[0]), int(s[1]), int(s[2]), int(s[3]))
        for s in stats[1:]
        if s[4] >= MIN_COMPONENT_AREA
    ]


def _overlap(a: Box, b: tuple[int, int, int, int]) -> float:
    """Area of the intersection of a and b."""
    iw = min(a[0] + a[2], b[0] + b[2]) - max(a[0], b[0])
    ih = min(a[1] + a[3], b[1] + b[3]) - max(a[1], b[1])
    return max(0.0, iw) * max(0.0, ih)


@dataclass
class Spec:
    video: str
    track_id: int
    start: int
    end: int
    keys: dict[int, Box]
    interpolate: list[tuple[int, int]]

    @classmethod
    def load(cls, path: Path) -> Spec:
        data = json.loads(path.read_text())
        keys = {
            int(f): (float(b[0]), float(b[1]), float(b[2]), float(b[3]))
            for f, b in data["keys"].items()
        }
        spans = [(int(a), int(b)) for a, b in data.get("interpolate", [])]
        spec = cls(
            data["video"], int(data["id"]), int(data["start"]), int(data["end"]), keys, spans
        )
        if spec.start not in keys:
            raise SystemExit(f"{path}: the start frame {spec.start} needs a key")
        for a, b in spans:
            if a not in keys or b not in keys or not a < b:
                raise SystemExit(f"{path}: interpolate [{a}, {b}] needs keys at both ends")
        return spec


def interpolate_box(a: Box, b: Box, s: float) -> Box:
    return (
        a[0] + s * (b[0] - a[0]),
        a[1] + s * (b[1] - a[1]),
        a[2] + s * (b[2] - a[2]),
        a[3] + s * (b[3] - a[3]),
    )


def follow(spec: Spec, masks: dict[int, Image]) -> tuple[dict[int, Box], dict[int, str]]:
    """Boxes for spec.start..spec.end and how each was made (key, auto, interp, unsure)."""
    boxes: dict[int, Box] = {}
    source: dict[int, str] = {}
    in_span = {f: (a, b) for a, b in spec.interpolate for f in range(a + 1, b)}
    vx = vy = 0.0
    prev: Box = spec.keys[spec.start]
    # slowly adapting target size: a silhouette much larger than this merged with something
    ref_w, ref_h = prev[2], prev[3]
    for f in range(spec.start, spec.end + 1):
        if f in spec.keys:
            box = spec.keys[f]
            kind = "key"
            ref_w, ref_h = box[2], box[3]
        elif f in in_span:
            a, b = in_span[f]
            box = interpolate_box(spec.keys[a], spec.keys[b], (f - a) / (b - a))
            kind = "interp"
        else:
            px, py, pw, ph = prev
            cx, cy = px + pw / 2 + vx, py + ph / 2 + vy
            predicted = (cx - ref_w / 2, cy - ref_h / 2, ref_w, ref_h)
            hits = [c for c in components(masks[f]) if _overlap(predicted, c) >= 0.2 * c[2] * c[3]]
            if hits:
                x0 = min(c[0] for c in hits)
                y0 = min(c[1] for c in hits)
                x1 = max(c[0] + c[2] for c in hits)
                y1 = max(c[1] + c[3] for c in hits)
                union: Box = (float(x0), float(y0), float(x1 - x0), float(y1 - y0))
            if hits and union[2] <= MAX_GROWTH_W * ref_w and union[3] <= MAX_GROWTH_H * ref_h:
                box = union
                kind = "auto"
                ref_w, ref_h = 0.8 * ref_w + 0.2 * union[2], 0.8 * ref_h + 0.2 * union[3]
            else:
                box = predicted
                kind = "unsure"
        if f > spec.start:
            cx, cy = box[0] + box[2] / 2, box[1] + box[3] / 2
            qx, qy = prev[0] + prev[2] / 2, prev[1] + prev[3] / 2
            vx, vy = 0.5 * vx + 0.5 * (cx - qx), 0.5 * vy + 0.5 * (cy - qy)
        boxes[f] = box
        source[f] = kind
        prev = box
    return boxes, source


def cmd_blobs(args: argparse.Namespace) -> int:
    frames = read_video(args.video)
    bg = median_background(frames)
    frame = frames[args.frame].copy()
    for i, (x, y, w, h) in enumerate(components(foreground(frames[args.frame], bg))):
        if w * h < 200:
            continue
        print(f"{i}: [{x}, {y}, {w}, {h}]")
        cv2.rectangle(frame, (x, y), (x + w, y + h), (0, 255, 0), 1)
        cv2.putText(frame, str(i), (x, y - 3), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 255), 1)
    cv2.imwrite(args.out, frame)
    return 0


def cmd_build(args: argparse.Namespace) -> int:
    specs = [Spec.load(Path(p)) for p in args.specs]
    videos = {s.video for s in specs}
    out_dir = Path(args.out_dir)
    for video in sorted(videos):
        frames = read_video(video)
        bg = median_background(frames)
        height, width = frames[0].shape[:2]
        fps = cv2.VideoCapture(video).get(cv2.CAP_PROP_FPS) or 10.0
        for spec in (s for s in specs if s.video == video):
            masks = {f: foreground(frames[f], bg) for f in range(spec.start, spec.end + 1)}
            boxes, source = follow(spec, masks)
            rounded = {
                f: (round(b[0], 1), round(b[1], 1), round(b[2], 1), round(b[3], 1))
                for f, b in boxes.items()
            }
            gt = GroundTruth(size=(width, height), fps=float(fps), tracks={spec.track_id: rounded})
            name = Path(video).stem
            path = out_dir / f"{name}_{spec.track_id}.json"
            save_ground_truth(gt, path)
            (out_dir / "specs" / f"{name}_{spec.track_id}.source.json").write_text(
                json.dumps({str(f): k for f, k in source.items()}) + "\n"
            )
            counts = {
                k: sum(1 for v in source.values() if v == k)
                for k in ("key", "auto", "interp", "unsure")
            }
            unsure = [f for f, k in source.items() if k == "unsure"]
            print(f"{path}: frames {spec.start}..{spec.end} {counts} unsure at {_ranges(unsure)}")
    return 0


def _ranges(frames: list[int]) -> str:
    out: list[str] = []
    for f in frames:
        if out and int(out[-1].split("-")[-1]) == f - 1:
            out[-1] = f"{out[-1].split('-')[0]}-{f}"
        else:
            out.append(str(f))
    return ",".join(out) or "-"


COLOURS = {
    "auto": (0, 255, 0),
    "key": (255, 128, 0),
    "interp": (0, 255, 255),
    "unsure": (0, 0, 255),
}


def cmd_review(args: argparse.Namespace) -> int:
    gt: GroundTruth = load_ground_truth(args.gt)
    boxes = gt.tracks[args.track]
    source_path = Path(args.gt).parent / "specs" / f"{Path(args.gt).stem}.source.json"
    source: dict[str, str] = json.loads(source_path.read_text()) if source_path.exists() else {}
    frames = read_video(args.video)
    first, last = min(boxes), max(boxes)
    start = first if args.start is None else args.start
    end = last if args.end is None else args.end
    tiles: list[Image] = []
    tile_h = args.tile_height
    for f in range(start, end + 1, args.every):
        if f not in boxes:
            continue
        x, y, w, h = boxes[f]
        cx, cy = x + w / 2, y + h / 2
        half_h = max(h, 60.0) * 0.8
        half_w = half_h * 0.6
        x0, y0 = int(max(0, cx - half_w)), int(max(0, cy - half_h))
        x1 = int(min(gt.size[0], cx + half_w))
        y1 = int(min(gt.size[1], cy + half_h))
        scale = tile_h / (2 * half_h)
        crop = frames[f][y0:y1, x0:x1]
        # (int(), not round(): a crop must never come out a pixel larger than its tile)
        size = (max(1, min(int((x1 - x0) * scale), int(2 * half_w * scale) + 2)),
                max(1, min(int((y1 - y0) * scale), tile_h)))  # fmt: skip
        tile = np.zeros((tile_h + 16, int(2 * half_w * scale) + 2, 3), np.uint8)
        if crop.size:  # empty when a coasting `unsure` box has left the image: a black tile
            crop = np.asarray(cv2.resize(crop, size), dtype=np.uint8)
            tile[16 : 16 + crop.shape[0], : crop.shape[1]] = crop
        colour = COLOURS.get(source.get(str(f), "auto"), (255, 255, 255))
        p0 = (int((x - x0) * scale), int((y - y0) * scale) + 16)
        p1 = (int((x + w - x0) * scale), int((y + h - y0) * scale) + 16)
        cv2.rectangle(tile, p0, p1, colour, 1)
        cv2.putText(tile, str(f), (2, 12), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (255, 255, 255), 1)
        tiles.append(tile)
    if not tiles:
        raise SystemExit("no frames to review")
    width = max(t.shape[1] for t in tiles)
    tiles = [np.pad(t, ((0, 0), (0, width - t.shape[1]), (0, 0))) for t in tiles]
    cols = args.columns
    tiles += [np.zeros_like(tiles[0])] * ((-len(tiles)) % cols)
    rows = [np.hstack(tiles[i : i + cols]) for i in range(0, len(tiles), cols)]
    cv2.imwrite(args.out, np.vstack(rows))
    print(f"{args.out}: {len(tiles)} tiles")
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m bench.annotate", description=__doc__.split("\n")[0]
    )
    sub = parser.add_subparsers(required=True)
    p = sub.add_parser("blobs", help="list foreground blobs of one frame")
    p.add_argument("--video", default="data/vtest.avi")
    p.add_argument("--frame", type=int, required=True)
    p.add_argument("--out", required=True)
    p.set_defaults(fn=cmd_blobs)
    p = sub.add_parser("build", help="build ground-truth files from specs")
    p.add_argument("specs", nargs="+")
    p.add_argument("--out-dir", default="bench/annotations")
    p.set_defaults(fn=cmd_build)
    p = sub.add_parser("review", help="contact sheet of the boxes of one track")
    p.add_argument("gt")
    p.add_argument("--track", type=int, required=True)
    p.add_argument("--video", default="data/vtest.avi")
    p.add_argument("--start", type=int)
    p.add_argument("--end", type=int)
    p.add_argument("--every", type=int, default=3)
    p.add_argument("--columns", type=int, default=12)
    p.add_argument("--tile-height", type=int, default=160)
    p.add_argument("--out", required=True)
    p.set_defaults(fn=cmd_review)
    args = parser.parse_args(argv)
    result: int = args.fn(args)
    return result


if __name__ == "__main__":
    sys.exit(main())
