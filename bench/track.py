"""ptzd's particle-filter tracker against OpenCV's CSRT, KCF and MIL on the same sequences.

    bash bench/setup_bench_venv.sh                 # once: .venv-bench with opencv-contrib
    .venv-bench/bin/python -m bench.track          # everything (several minutes on 2 cores)
    .venv-bench/bin/python -m bench.track --quick  # a subset: vtest + one seed, 60 frames each

Sequence classes:
- `vtest`: the hand-checked pedestrians of bench/annotations/vtest_*.json on data/vtest.avi
  (`./scripts/fetch-vtest.sh`), static camera, 768x576.
- `synthetic-static`: the simulator's procedural scene (`synthetic:SEED`) with its exact
  ground truth, the wide video as it is.
- `synthetic-moving`: the same scene seen through the PTZ camera model along a scripted
  pan/tilt/zoom path (it follows the target loosely and sways, so the background moves and the
  target's scale changes); ground truth projected into the view. ptzd's tracker gets the exact
  inter-frame homography as ego-motion, as the daemon's control loop supplies it; the OpenCV
  trackers have no such input (the `ptzd-noego` entry shows ptzd without it).

Every tracker starts from the ground-truth box of a sequence's first frame and is scored on
the other frames with ground truth (ptzd.metrics: OTB success AUC, precision at 20 px, lost
frames). Frames are decoded/rendered before tracking, so the frames/s column is tracking only.
The speed section times each tracker on vtest frames (768x576), ptzd with N = 100 and with its
default N (also with the seed's hard value bins, `color.value_blend = 0`, for what the
default soft bins cost), pinned to one core, the median of `--repeats` runs.

Prints a table, writes bench/results/track.json and bench/results/track_success.png.
The machine is shared (2 cores, other work running): frame rates are noisy; compare the
trackers of one run, not runs of different days.
"""

# Before numpy loads: one BLAS/OpenMP thread, so "one core" means one core.
import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import datetime  # noqa: E402
import importlib.util  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import platform  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from collections.abc import Callable, Iterator  # noqa: E402
from dataclasses import dataclass, field  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any, Protocol  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402
import numpy.typing as npt  # noqa: E402

from ptzd.metrics import IOU_THRESHOLDS, Box, SequenceScore, score_sequence  # noqa: E402
from ptzd.sim.groundtruth import load_ground_truth  # noqa: E402
from ptzd.vision.features import to_bgr, to_grey  # noqa: E402

Frame = npt.NDArray[np.uint8]
Matrix = npt.NDArray[np.float64]

REPO = Path(__file__).resolve().parents[1]
RESULTS = REPO / "bench" / "results"
ANNOTATIONS = REPO / "bench" / "annotations"
VTEST = REPO / "data" / "vtest.avi"
CLASSES = ("vtest", "synthetic-static", "synthetic-moving")
PEERS = ("csrt", "kcf", "mil")
DEFAULT_TRACKERS = ("ptzd", "csrt", "kcf", "mil")


# --- sequences --------------------------------------------------------------------------


@dataclass
class Sequence:
    """Pre-decoded frames with ground truth keyed by index into `frames` (0 = init frame)."""

    name: str
    cls: str
    frames: list[Frame]
    truth: dict[int, Box]
    # ego-motion per frame index i >= 1: homography from frame i-1's pixels to frame i's
    ego: dict[int, Matrix] = field(default_factory=dict)
    note: str = ""


def scaled(seq: Sequence, factor: float) -> Sequence:
    """`seq` as a camera of `factor` times the resolution would see it: frames resized
    (area-averaged when shrinking), truth boxes and ego-motion homographies scaled alike."""
    if factor <= 0:
        raise ValueError(f"scale factor must be positive, got {factor}")
    if factor == 1.0:
        return seq
    interpolation = cv2.INTER_AREA if factor < 1 else cv2.INTER_LINEAR
    frames: list[Frame] = [
        np.asarray(cv2.resize(f, None, fx=factor, fy=factor, interpolation=interpolation), np.uint8)
        for f in seq.frames
    ]
    truth = {i: (b[0] * factor, b[1] * factor, b[2] * factor, b[3] * factor)
             for i, b in seq.truth.items()}  # fmt: skip
    s = np.diag([factor, factor, 1.0])
    ego = {i: s @ h @ np.linalg.inv(s) for i, h in seq.ego.items()}
    note = f"{seq.note}, x{factor:g}" if seq.note else f"x{factor:g}"
    return Sequence(seq.name, seq.cls, frames, truth, ego, note)


def greyed(seq: Sequence) -> Sequence:
    """`seq` as a monochrome camera (a day/night camera at night) sees it: single-channel."""
    note = f"{seq.note}, grey" if seq.note else "grey"
    return Sequence(seq.name, seq.cls, [to_grey(f) for f in seq.frames], seq.truth, seq.ego, note)


def dusk(seq: Sequence, at: float) -> Sequence:
    """`seq` with a day/night camera going to night mode `at` (a fraction of its length) of
    the way through: from that frame on grey, in three equal channels as a decoder gives them."""
    if not 0.0 <= at <= 1.0:
        raise ValueError(f"dusk must be within 0..1 of the sequence, got {at}")
    start = round(at * len(seq.frames))
    frames = [f if i < start else to_bgr(to_grey(f)) for i, f in enumerate(seq.frames)]
    note = f"{seq.note}, grey from {start}" if seq.note else f"grey from {start}"
    return Sequence(seq.name, seq.cls, frames, seq.truth, seq.ego, note)


def vtest_sequences(max_frames: int | None, only: set[str] | None) -> Iterator[Sequence]:
    if not VTEST.is_file():
        print(f"vtest: skipped, {VTEST} missing (run ./scripts/fetch-vtest.sh)", file=sys.stderr)
        return
    from ptzd.sim.sources import open_wide_source

    source = open_wide_source(str(VTEST))
    for path in sorted(ANNOTATIONS.glob("vtest_*.json")):
        name = path.stem
        if only and name not in only:
            continue
        gt = load_ground_truth(path, expected_size=source.size)
        for track_id, boxes in sorted(gt.tracks.items()):
            first, last = min(boxes), max(boxes)
            if max_frames is not None:
                last = min(last, first + max_frames - 1)
            frames = [source.read(i) for i in range(first, last + 1)]
            truth = {f - first: b for f, b in boxes.items() if first <= f <= last}
            yield Sequence(
                name if len(gt.tracks) == 1 else f"{name}#{track_id}",
                "vtest",
                frames,
                truth,
                note=f"frames {first}..{last}",
            )


def fair_start(gt: Any, tid: int, frame: int) -> bool:
    """Whether walker `tid` makes a fair init box in `frame`: at least 20 px tall and 8 wide,
    at least 80 % visible, clear of the frame border."""
    x, y, w, h = gt.tracks[tid][frame]
    width, height = gt.size
    if h < 20 or w < 8 or gt.visibility.get(tid, {}).get(frame, 1.0) < 0.8:
        return False
    return bool(x > 0 and y > 0 and x + w < width and y + h < height)


def span_end(boxes: dict[int, Box], first: int, max_frames: int) -> int:
    """The last frame of the run of frames with a box from `first`, at most `max_frames`."""
    last = first
    while last + 1 in boxes and last + 1 - first < max_frames:
        last += 1
    return last


def _pick_targets(
    gt: Any, horizon: int, count: int, max_frames: int, min_frames: int = 60
) -> list[tuple[int, int, int]]:
    """(track id, first, last) of up to `count` sequences within the first `horizon` frames.

    A sequence starts on a frame where the person is at least 20 px tall, at least 80 %
    visible and clear of the frame border (a fair init box for every tracker), and runs while
    the track has a box (occluded frames included: the truth is amodal), for up to
    `max_frames` frames. The longest sequences win.
    """
    spans: list[tuple[int, int, int, int]] = []
    for tid, boxes in gt.tracks.items():
        for f in sorted(f for f in boxes if f < horizon):
            if not fair_start(gt, tid, f):
                continue
            last = span_end(boxes, f, max_frames)
            if last - f + 1 >= min_frames:
                spans.append((last - f, tid, f, last))
            break
    spans.sort(key=lambda s: (-s[0], s[2]))
    return [(tid, first, last) for _, tid, first, last in spans[:count]]


def _aim(model: Any, point: tuple[float, float]) -> tuple[float, float]:
    """Pan and tilt (degrees) that put wide pixel `point` at the view centre."""
    ray = model.K_wide_inv @ np.array([point[0], point[1], 1.0])
    ray /= np.linalg.norm(ray)
    # view axis R_pan(p) R_tilt(t) e_z = (cos t sin p, -sin t, cos t cos p)
    tilt = math.degrees(math.asin(-ray[1]))
    pan = math.degrees(math.atan2(ray[0], ray[2]))
    return pan, tilt


def synthetic_sequences(
    seeds: list[int],
    classes: set[str],
    max_frames: int,
    targets_per_seed: int,
    wide_hfov: float,
) -> Iterator[Sequence]:
    try:
        from ptzd.sim.sources import open_wide_source

        sources = {seed: open_wide_source(f"synthetic:{seed}") for seed in seeds}
    except ImportError as exc:  # the procedural scene is another helper's work in progress
        print(f"synthetic: skipped, the scene is not available ({exc})", file=sys.stderr)
        return
    from ptzd.control.egomotion import view_homography
    from ptzd.sim.camera_model import CameraModel, Pose

    for seed, source in sources.items():
        gt = source.ground_truth
        if gt is None:
            print(f"synthetic:{seed}: skipped, no ground truth", file=sys.stderr)
            continue
        picks = _pick_targets(gt, 2 * max_frames, targets_per_seed, max_frames)
        if not picks:
            print(f"synthetic:{seed}: skipped, no track long enough", file=sys.stderr)
            continue
        needed = sorted({i for _, first, last in picks for i in range(first, last + 1)})
        wide = {i: source.read(i) for i in needed}
        for tid, first, last in picks:
            boxes = gt.tracks[tid]
            name = f"synthetic:{seed}#{tid}"
            if "synthetic-static" in classes:
                yield Sequence(
                    name,
                    "synthetic-static",
                    [wide[i] for i in range(first, last + 1)],
                    {i - first: boxes[i] for i in range(first, last + 1) if i in boxes},
                    note=f"frames {first}..{last}",
                )
            if "synthetic-moving" in classes:
                yield _moving_view(
                    name,
                    wide,
                    boxes,
                    first,
                    last,
                    gt.size,
                    wide_hfov,
                    CameraModel,
                    Pose,
                    view_homography,
                )


def _moving_view(
    name: str,
    wide: dict[int, Frame],
    boxes: dict[int, Box],
    first: int,
    last: int,
    wide_size: tuple[int, int],
    wide_hfov: float,
    camera_model: Callable[..., Any],
    pose_type: Callable[..., Any],
    view_homography: Callable[..., Matrix],
) -> Sequence:
    """The wide frames through the PTZ camera model along a scripted path.

    The path aims at the target's centre smoothed over +-10 frames (a lagging operator), sways
    +-4 degrees in pan (period 80 frames) and +-2 in tilt (period 110), and zooms between
    hfov 28 and 40 degrees (period 150): the background moves every frame, the target drifts
    in the view and changes scale.
    """
    view_size = (640, 480)
    model = camera_model(wide_size, wide_hfov, view_size)
    centres = {
        i: (b[0] + b[2] / 2, b[1] + b[3] / 2) for i, b in boxes.items() if first <= i <= last
    }
    frames: list[Frame] = []
    truth: dict[int, Box] = {}
    ego: dict[int, Matrix] = {}
    prev_pose = None
    known = sorted(centres)
    for k, i in enumerate(range(first, last + 1)):
        window = [centres[j] for j in range(i - 10, i + 11) if j in centres] or [
            centres[min(known, key=lambda j: abs(j - i))]
        ]
        cx = sum(c[0] for c in window) / len(window)
        cy = sum(c[1] for c in window) / len(window)
        pan, tilt = _aim(model, (cx, cy))
        pose = pose_type(
            pan + 4.0 * math.sin(2 * math.pi * k / 80.0),
            tilt + 2.0 * math.sin(2 * math.pi * k / 110.0),
            34.0 + 6.0 * math.sin(2 * math.pi * k / 150.0),
        )
        frames.append(model.render(wide[i], pose))
        if i in boxes:
            projected = model.box_to_view(boxes[i], pose)
            if projected is not None and projected[2] >= 2 and projected[3] >= 2:
                truth[k] = projected
        if prev_pose is not None:
            ego[k] = view_homography(view_size, prev_pose, pose)
        prev_pose = pose
    note = f"frames {first}..{last}, 640x480 view"
    return Sequence(f"{name} ptz", "synthetic-moving", frames, truth, ego, note=note)


# --- trackers ---------------------------------------------------------------------------


class BenchTracker(Protocol):
    name: str

    def init(self, frame: Frame, box: Box) -> None: ...

    def update(self, frame: Frame, ego: Matrix | None) -> Box | None:
        """The box in `frame`, or None when the tracker reports the target lost."""
        ...


class PtzdTracker:
    """ptzd's tracker through its Python API; LOST counts as null (as `ptzd track` writes)."""

    def __init__(
        self,
        name: str,
        particles: int | None,
        seed: int,
        use_ego: bool,
        color: dict[str, Any] | None = None,
    ) -> None:
        from ptzd.vision.config import ColorConfig, TrackerConfig

        self.name = name
        overrides: dict[str, Any] = {"kind": "color", "seed": seed}  # the colour filter
        if particles is not None:
            overrides["num_particles"] = particles
        if color is not None:
            overrides["color"] = ColorConfig(**color)
        self.config = TrackerConfig(**overrides)
        self.use_ego = use_ego
        self._tracker: Any = None

    def init(self, frame: Frame, box: Box) -> None:
        from ptzd.vision.tracking import make_tracker

        self._tracker = make_tracker(self.config)
        self._tracker.init(frame, box)

    def update(self, frame: Frame, ego: Matrix | None) -> Box | None:
        from ptzd.vision.tracking import TrackState

        result = self._tracker.update(frame, ego if self.use_ego else None)
        if result.state is TrackState.LOST:
            return None
        box: Box = result.box
        return box


def opencv_tracker_factory(kind: str) -> Callable[[], Any]:
    """`cv2.TrackerX.create` (OpenCV >= 4.5.1, including 5.x) or `cv2.legacy.TrackerX_create`."""
    cls_name = f"Tracker{kind.upper()}"
    cls = getattr(cv2, cls_name, None)
    if cls is not None and hasattr(cls, "create"):
        create: Callable[[], Any] = cls.create
        return create
    legacy = getattr(cv2, "legacy", None)
    if legacy is not None and hasattr(legacy, f"{cls_name}_create"):
        legacy_create: Callable[[], Any] = getattr(legacy, f"{cls_name}_create")
        return legacy_create
    raise LookupError(
        f"cv2 {cv2.__version__} has no {cls_name}: run in .venv-bench "
        "(opencv-contrib-python-headless, bench/setup_bench_venv.sh)"
    )


# OpenCV's peers are not started on a box narrower or lower than this (px).
MIN_PEER_BOX = 4


class OpenCVTracker:
    """An OpenCV tracker; `update` returning ok=False counts as null."""

    def __init__(self, kind: str, create: Callable[[], Any] | None = None) -> None:
        self.name = kind
        self._create = create or opencv_tracker_factory(kind)
        self._tracker: Any = None

    def init(self, frame: Frame, box: Box) -> None:
        x, y, w, h = box
        x0, y0 = round(x), round(y)
        rect = (x0, y0, max(1, round(x + w) - x0), max(1, round(y + h) - y0))
        self._tracker = None  # a peer that cannot start scores as lost on every frame
        if min(rect[2:]) < MIN_PEER_BOX:
            # synthetic-thermal:2's second track starts as a walker's first pixel (1 x 1 at
            # x = 0): on it OpenCV 5.1's MIL never returns and CSRT raises
            print(f"  {self.name}: not started on a box of {rect[2]} x {rect[3]} px")
            return
        tracker = self._create()
        try:
            tracker.init(frame, rect)
        except cv2.error as exc:
            print(f"  {self.name}: init failed on {rect}: {str(exc).strip().splitlines()[-1]}")
            return
        self._tracker = tracker

    def update(self, frame: Frame, ego: Matrix | None) -> Box | None:
        if self._tracker is None:
            return None
        ok, rect = self._tracker.update(frame)
        if not ok:
            return None
        x, y, w, h = (float(v) for v in rect)
        return (x, y, w, h)


def make_bench_tracker(name: str, particles: int | None, seed: int) -> BenchTracker:
    if name == "ptzd":
        return PtzdTracker(name, particles, seed, use_ego=True)
    if name == "ptzd-noego":
        return PtzdTracker(name, particles, seed, use_ego=False)
    if name in PEERS:
        return OpenCVTracker(name)
    raise SystemExit(f"unknown tracker {name!r}: choose from ptzd, ptzd-noego, csrt, kcf, mil")


# --- running ----------------------------------------------------------------------------


@dataclass
class Run:
    score: SequenceScore
    fps: float
    boxes: dict[int, Box | None]


def run_tracker(tracker: BenchTracker, seq: Sequence) -> Run:
    """Init on frame 0 with its ground truth, track frames 1.., score frames 1.. with truth."""
    if 0 not in seq.truth:
        raise ValueError(f"{seq.name}: no ground truth in the first frame")
    tracker.init(seq.frames[0], seq.truth[0])
    boxes: dict[int, Box | None] = {0: seq.truth[0]}
    elapsed = 0.0
    for i in range(1, len(seq.frames)):
        frame = seq.frames[i]
        ego = seq.ego.get(i)
        t0 = time.perf_counter()
        boxes[i] = tracker.update(frame, ego)
        elapsed += time.perf_counter() - t0
    tracked = len(seq.frames) - 1
    score = score_sequence(boxes, seq.truth, start=1)
    return Run(score, tracked / elapsed if elapsed > 0 else math.inf, boxes)


HARD_BINS: dict[str, Any] = {"value_blend": 0.0}  # the seed's colour bins (speed rows)


def speed_test(
    frames: list[Frame], init: Box, trackers: list[str], seed: int, repeats: int, n_default: int
) -> dict[str, dict[str, Any]]:
    """Median tracked frames/s of each tracker over `repeats` runs on `frames`."""
    entries: list[tuple[str, Callable[[], BenchTracker]]] = []
    for name in trackers:
        if name == "ptzd":
            entries.append(("ptzd N=100", lambda: PtzdTracker("ptzd", 100, seed, True)))
            if n_default != 100:
                entries.append(
                    (f"ptzd N={n_default}", lambda: PtzdTracker("ptzd", None, seed, True))
                )
            # the seed's hard value bins, for what the default soft ones cost
            entries.append(
                (
                    "ptzd N=100 hard bins",
                    lambda: PtzdTracker("ptzd", 100, seed, True, color=HARD_BINS),
                )
            )
            if n_default != 100:
                entries.append(
                    (
                        f"ptzd N={n_default} hard bins",
                        lambda: PtzdTracker("ptzd", None, seed, True, color=HARD_BINS),
                    )
                )
        elif name in PEERS:
            entries.append((name, lambda name=name: OpenCVTracker(name)))  # type: ignore[misc]
    out: dict[str, dict[str, Any]] = {}
    for label, factory in entries:
        rates = []
        for _ in range(repeats):
            tracker = factory()
            tracker.init(frames[0], init)
            t0 = time.perf_counter()
            for frame in frames[1:]:
                tracker.update(frame, None)
            rates.append((len(frames) - 1) / (time.perf_counter() - t0))
        out[label] = {"median_fps": statistics.median(rates), "runs": rates}
        print(
            f"  {label:<22} {statistics.median(rates):8.1f} frames/s  (runs: "
            + ", ".join(f"{r:.0f}" for r in rates)
            + ")"
        )
    return out


def summarise(results: list[dict[str, Any]], trackers: list[str]) -> dict[str, Any]:
    """Per class and tracker: mean AUC, mean precision@20, lost/scored frames, median fps."""
    summary: dict[str, Any] = {}
    for cls in CLASSES:
        rows = [r for r in results if r["class"] == cls]
        if not rows:
            continue
        summary[cls] = {}
        for name in trackers:
            runs = [r["trackers"][name] for r in rows if name in r["trackers"]]
            if not runs:
                continue
            summary[cls][name] = {
                "sequences": len(runs),
                "auc": statistics.fmean(run["auc"] for run in runs),
                "precision_20": statistics.fmean(run["precision_20"] for run in runs),
                "lost_frames": sum(run["lost_frames"] for run in runs),
                "frames": sum(run["frames"] for run in runs),
                "median_fps": statistics.median(run["fps"] for run in runs),
                "success": [
                    statistics.fmean(run["success"][k] for run in runs)
                    for k in range(len(IOU_THRESHOLDS))
                ],
            }
    return summary


def print_table(
    results: list[dict[str, Any]], summary: dict[str, Any], trackers: list[str]
) -> None:
    head = f"{'sequence':<26}{'frames':>7} " + " ".join(f"{t:>24}" for t in trackers)
    sub = f"{'':<26}{'':>7} " + " ".join(f"{'AUC  P@20 lost    fps':>24}" for _ in trackers)
    print()
    print(head)
    print(sub)
    for r in results:
        cells = []
        for t in trackers:
            run = r["trackers"].get(t)
            if run is None:
                cells.append(f"{'-':>24}")
                continue
            cells.append(
                f"{run['auc']:.3f} {run['precision_20']:.2f} {run['lost_frames']:4d} "
                f"{run['fps']:6.0f}".rjust(24)
            )
        print(f"{r['name'][:25]:<26}{r['frames']:>7} " + " ".join(cells))
    print()
    print("per class (mean AUC, mean precision@20, lost/scored frames, median fps)")
    for cls, per in summary.items():
        cells = []
        for t in trackers:
            s = per.get(t)
            if s is None:
                cells.append(f"{'-':>24}")
                continue
            lost = f"{s['lost_frames']}/{s['frames']}"
            cells.append(
                f"{s['auc']:.3f} {s['precision_20']:.2f} {lost:>7} {s['median_fps']:5.0f}".rjust(24)
            )
        n = max(s["sequences"] for s in per.values())
        print(f"{cls + f' ({n})':<26}{'':>7} " + " ".join(cells))


def plot(summary: dict[str, Any], trackers: list[str], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    classes = list(summary)
    fig, axes = plt.subplots(1, len(classes), figsize=(5 * len(classes), 4), squeeze=False)
    for ax, cls in zip(axes[0], classes, strict=True):
        for name in trackers:
            s = summary[cls].get(name)
            if s is None:
                continue
            ax.plot(IOU_THRESHOLDS, s["success"], label=f"{name} [{s['auc']:.3f}]")
        ax.set_title(f"{cls} ({max(v['sequences'] for v in summary[cls].values())} sequences)")
        ax.set_xlabel("overlap threshold (IoU)")
        ax.set_ylabel("success rate")
        ax.set_xlim(0, 1)
        ax.set_ylim(0, 1.02)
        ax.grid(alpha=0.3)
        ax.legend(loc="lower left", fontsize=8)
    fig.suptitle("Success plots (OTB); legend: AUC")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def source_fingerprint() -> str:
    """SHA-1 over ptzd's source files: which code state a result file was measured on."""
    import hashlib

    digest = hashlib.sha1()
    for path in sorted((REPO / "ptzd").rglob("*.py")):
        digest.update(path.relative_to(REPO).as_posix().encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()[:12]


def _csv(text: str) -> list[str]:
    return [t.strip() for t in text.split(",") if t.strip()]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m bench.track", description=__doc__.split("\n")[0] if __doc__ else None
    )
    parser.add_argument(
        "--trackers",
        default=",".join(DEFAULT_TRACKERS),
        help="comma list of ptzd, ptzd-noego, csrt, kcf, mil",
    )
    parser.add_argument("--classes", default=",".join(CLASSES), help="comma list of classes")
    parser.add_argument("--sequences", default="", help="only these vtest files (vtest_2,...)")
    parser.add_argument("--seeds", default="1,2", help="synthetic scene seeds")
    parser.add_argument("--targets-per-seed", type=int, default=2)
    parser.add_argument("--max-frames", type=int, default=300, help="per sequence")
    parser.add_argument("--wide-hfov", type=float, default=90.0, help="of the synthetic scene")
    parser.add_argument(
        "--particles",
        type=int,
        default=None,
        help="ptzd particle count (default: the tracker config's)",
    )
    parser.add_argument("--seed", type=int, default=0, help="ptzd tracker seed")
    parser.add_argument("--repeats", type=int, default=3, help="speed-test repeats")
    parser.add_argument("--no-speed", action="store_true", help="skip the speed test")
    parser.add_argument("--speed-only", action="store_true", help="only the speed test")
    parser.add_argument("--all-cores", action="store_true", help="do not pin to one core")
    parser.add_argument(
        "--quick", action="store_true", help="vtest + seed 1, one target, 60 frames, 1 repeat"
    )
    parser.add_argument("--out", type=Path, default=RESULTS / "track.json")
    parser.add_argument("--png", type=Path, default=RESULTS / "track_success.png")
    args = parser.parse_args(argv)
    if args.quick:
        args.seeds, args.targets_per_seed, args.max_frames, args.repeats = "1", 1, 60, 1

    trackers = _csv(args.trackers)
    classes = set(_csv(args.classes))
    unknown = classes - set(CLASSES)
    if unknown:
        raise SystemExit(f"unknown classes {sorted(unknown)}: choose from {', '.join(CLASSES)}")
    for name in trackers:
        if name in PEERS:
            try:
                opencv_tracker_factory(name)  # fail early outside .venv-bench
            except LookupError as exc:
                raise SystemExit(str(exc)) from None
    if not args.all_cores and hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
        cv2.setNumThreads(1)
    from ptzd.vision.config import TrackerConfig

    n_default = args.particles or TrackerConfig().num_particles
    meta = {
        "date": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "python": platform.python_version(),
        "machine": platform.machine(),
        "cpu_count": os.cpu_count(),
        "pinned_to_one_core": not args.all_cores,
        "opencv": cv2.__version__,
        "numpy": np.__version__,
        "ptzd_particles": n_default,
        "ptzd_source_sha1": source_fingerprint(),
        "argv": sys.argv[1:] if argv is None else argv,
        "note": "shared 2-core machine: frame rates are noisy; compare trackers of one run",
    }
    print(
        f"ptzd source {meta['ptzd_source_sha1']}, OpenCV {cv2.__version__}, "
        f"ptzd N = {n_default}, {'one core' if not args.all_cores else 'all cores'}",
        flush=True,
    )
    results: list[dict[str, Any]] = []
    speed: dict[str, Any] = {}

    if not args.speed_only:
        only = set(_csv(args.sequences)) or None
        max_frames = args.max_frames
        sources: list[Iterator[Sequence]] = []
        if "vtest" in classes:
            sources.append(vtest_sequences(max_frames, only))
        synthetic = classes & {"synthetic-static", "synthetic-moving"}
        if synthetic:
            seeds = [int(s) for s in _csv(args.seeds)]
            sources.append(
                synthetic_sequences(
                    seeds, synthetic, max_frames, args.targets_per_seed, args.wide_hfov
                )
            )
        for source in sources:
            for seq in source:
                if 0 not in seq.truth:
                    print(f"{seq.name}: skipped, no ground truth in its first frame")
                    continue
                entry: dict[str, Any] = {
                    "name": seq.name,
                    "class": seq.cls,
                    "note": seq.note,
                    "frames": len(seq.frames),
                    "size": [seq.frames[0].shape[1], seq.frames[0].shape[0]],
                    "trackers": {},
                }
                line = f"{seq.cls:<17} {seq.name:<24} {len(seq.frames):4d} frames:"
                for name in trackers:
                    run = run_tracker(make_bench_tracker(name, args.particles, args.seed), seq)
                    entry["trackers"][name] = {**run.score.to_json(), "fps": run.fps}
                    line += f"  {name} {run.score.auc:.3f}/{run.fps:.0f}fps"
                print(line, flush=True)
                results.append(entry)

    if not args.no_speed and VTEST.is_file():
        from ptzd.sim.sources import open_wide_source

        gt_path = ANNOTATIONS / "vtest_2.json"
        gt = load_ground_truth(gt_path)
        boxes = next(iter(gt.tracks.values()))
        first = min(boxes)
        video = open_wide_source(str(VTEST))
        n_speed = 100 if args.quick else 146
        frames = [video.read(i) for i in range(first, first + n_speed)]
        cores = "all cores" if args.all_cores else "one core"
        print(
            f"\nspeed: {len(frames) - 1} frames of {gt_path.name} (768x576), "
            f"median of {args.repeats}, {cores}"
        )
        speed = {
            "sequence": gt_path.stem,
            "frames": len(frames) - 1,
            "size": [768, 576],
            "repeats": args.repeats,
            "trackers": speed_test(
                frames, boxes[first], trackers, args.seed, args.repeats, n_default
            ),
        }

    summary = summarise(results, trackers)
    if results:
        print_table(results, summary, trackers)
    # the results first: the plot needs matplotlib, which only the bench venv has
    args.out.parent.mkdir(parents=True, exist_ok=True)
    doc = {"meta": meta, "sequences": results, "classes": summary, "speed": speed}
    args.out.write_text(json.dumps(doc, indent=1, default=float) + "\n")
    print(f"\nwrote {args.out}")
    if results:
        if importlib.util.find_spec("matplotlib") is None:
            print(f"no plot ({args.png}): matplotlib is in the bench venv, not here")
        else:
            plot(summary, trackers, args.png)
            print(f"wrote {args.png}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
