"""`ptzd sim` without a subcommand: the simulated dome and the daemon, closed over real bytes.

The simulator (`ptzd.sim`) renders the dome's view of a wide video or synthetic scene; the
daemon (`ptzd.app.Daemon`, the same pipeline `ptzd run` uses) tracks the target in it and
writes Pelco bytes to a pty whose other end is the simulated dome. With `--virtual-clock`
the run is deterministic and as fast as the work allows: the tracker runs on the event loop
and virtual time advances only when every task waits.

`--record DIR` writes `camera.jsonl` and `serial.jsonl` (the simulator's recorder),
`track.jsonl` (per processed frame: capture time, box, state), `report.json` and
`report.png`; `--view OUT.mp4` a video of what the dome saw with the track drawn on it
(rendered again after the run, so it costs the live loop nothing). The report scores the run
from what was rendered: the target's ground-truth centre is projected into each rendered view
with the documented camera model.
"""

from __future__ import annotations

import asyncio
import itertools
import json
import math
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO

from ptzd.errors import UsageError

if TYPE_CHECKING:
    from ptzd.app import TrackItem
    from ptzd.config import Config
    from ptzd.control.controller import ControlDecision
    from ptzd.sim.camera_model import CameraModel, Pose
    from ptzd.sim.config import SimConfig
    from ptzd.sim.groundtruth import GroundTruth

BoxTuple = tuple[float, float, float, float]
TARGET_VIEW_FRACTION = 1 / 3  # the target starts about a third of the view height
REVERSAL_WINDOW_S = 10.0


def add_arguments(parser: Any) -> None:
    """The closed loop's options on the `sim` parser (which also has `render`)."""
    source = parser.add_mutually_exclusive_group()
    source.add_argument("--video", metavar="PATH", help="wide video file")
    source.add_argument(
        "--scene", metavar="synthetic[:SEED]", help="procedural wide scene (default synthetic:0)"
    )
    parser.add_argument("--wide-hfov", type=float, metavar="DEG", help="override sim.wide_hfov")
    parser.add_argument("--gt", metavar="GT.json", help="ground truth of the wide video")
    parser.add_argument(
        "--target",
        type=int,
        metavar="ID",
        help="ground-truth track to follow (a synthetic scene's walker needs no --gt)",
    )
    parser.add_argument("--duration", type=float, metavar="S", help="stop after S seconds")
    parser.add_argument("--record", metavar="DIR", help="write jsonl records and the report")
    parser.add_argument(
        "--view", metavar="OUT.mp4", help="write the dome's view with the track drawn on it"
    )
    parser.add_argument(
        "--virtual-clock", action="store_true", help="deterministic, as fast as possible"
    )
    parser.add_argument(
        "--acquire",
        action="store_true",
        help="start with no target: the daemon's detector finds one (scored on the walker "
        "the dome starts pointed at)",
    )
    parser.add_argument(
        "--loop",
        action="store_true",
        help="with --acquire and --duration: play the wide source round and round (long "
        "unattended runs; scored on the first pass)",
    )
    parser.add_argument("--config", metavar="FILE", help="TOML config (default: built-in)")
    parser.add_argument("--mqtt-url", metavar="URL", help="publish over MQTT (mqtt://HOST:PORT)")
    parser.add_argument("--camera-name", metavar="NAME", help="camera name for MQTT topics")


def handle(args: Any) -> int:
    """Handler of `ptzd sim` (no subcommand)."""
    from ptzd.daemon_cli import configure_logging_from

    options = ClosedLoopOptions.from_args(args)
    configure_logging_from(options.config, args)
    report = asyncio.run(run_closed_loop(options))
    print(json.dumps(summary(report), sort_keys=True))
    return 0


def run_sim_capture(config: Config, init: BoxTuple | None) -> int:
    """`ptzd run` with `capture.source = "sim"`: the closed loop on a synthetic scene."""
    if init is not None:
        raise UsageError("--init is not used with capture.source = 'sim' (a walker is picked)")
    report = asyncio.run(run_closed_loop(ClosedLoopOptions(config=config, spec="synthetic:0")))
    print(json.dumps(summary(report), sort_keys=True))
    return 0


@dataclass(frozen=True)
class ClosedLoopOptions:
    config: Config
    spec: str = "synthetic:0"
    is_video: bool = False
    wide_hfov: float | None = None
    gt_path: str | None = None
    target: int | None = None
    duration: float | None = None
    record: Path | None = None
    view: Path | None = None
    virtual: bool = False
    mqtt_url: str | None = None
    camera_name: str | None = None
    acquire: bool = False  # no initial box: the daemon's own detection must lock on
    loop: bool = False  # play the wide source round and round (needs acquire and duration)

    @classmethod
    def from_args(cls, args: Any) -> ClosedLoopOptions:
        from ptzd.config import load_config, validate_config

        config = load_config(args.config) if args.config else validate_config({})
        from pydantic import ValidationError

        try:
            if args.mqtt_url:
                mqtt = config.mqtt.model_validate(
                    {**config.mqtt.model_dump(), "enabled": True, "url": args.mqtt_url}
                )
                config = config.model_copy(update={"mqtt": mqtt})
            if args.camera_name:
                camera = config.camera.model_validate({"name": args.camera_name})
                config = config.model_copy(update={"camera": camera})
        except ValidationError as exc:
            problem = exc.errors(include_url=False)[0]
            raise UsageError(f"--mqtt-url/--camera-name: {problem['msg']}") from None
        if args.gt is not None and args.target is None:
            raise UsageError("--gt needs --target ID (the track to follow)")
        if args.video and args.gt is None:
            raise UsageError("--video needs --gt GT.json --target ID (the target to follow)")
        if getattr(args, "loop", False) and not (getattr(args, "acquire", False) and args.duration):
            raise UsageError("--loop needs --acquire and --duration S")
        if args.duration is not None and not args.duration > 0:
            raise UsageError(f"--duration must be positive; got {args.duration}")
        if args.wide_hfov is not None and not 1.0 < args.wide_hfov < 179.0:
            raise UsageError(f"--wide-hfov must be in (1, 179) degrees; got {args.wide_hfov}")
        return cls(
            config=config,
            spec=args.video or args.scene or "synthetic:0",
            is_video=bool(args.video),
            wide_hfov=args.wide_hfov,
            gt_path=args.gt,
            target=args.target,
            duration=args.duration,
            record=Path(args.record) if args.record else None,
            view=Path(args.view) if getattr(args, "view", None) else None,
            virtual=bool(args.virtual_clock),
            mqtt_url=args.mqtt_url,
            camera_name=args.camera_name,
            acquire=bool(getattr(args, "acquire", False)),
            loop=bool(getattr(args, "loop", False)),
        )


# --- geometry -------------------------------------------------------------------------------


def pose_towards(model: CameraModel, box: BoxTuple, sim: SimConfig) -> Pose:
    """The pose looking at the centre of wide `box` with the box a third of the view high."""
    import numpy as np

    from ptzd.sim.camera_model import Pose

    x, y, w, h = box
    ray = model.K_wide_inv @ np.array([x + w / 2, y + h / 2, 1.0])
    dx, dy, dz = (float(v) for v in ray)
    pan = math.degrees(math.atan2(dx, dz))
    tilt = math.degrees(math.atan2(-dy, math.hypot(dx, dz)))
    focal_wide = float(model.K_wide[0, 0])
    angle = h / focal_wide  # angular height of the target (radians, small-angle)
    view_w, view_h = model.view_size
    focal_view = view_h * TARGET_VIEW_FRACTION / max(angle, 1e-6)
    hfov = math.degrees(2 * math.atan((view_w / 2) / focal_view))
    hfov = min(sim.zoom_hfov_wide, max(sim.zoom_hfov_tele, hfov))
    return Pose(pan, tilt, hfov)


def zoom_position(sim: SimConfig, hfov: float) -> float:
    """The dome's zoom position (0 wide .. 1 tele) for a horizontal FOV."""
    magnification = math.tan(math.radians(sim.zoom_hfov_wide) / 2) / math.tan(
        math.radians(hfov) / 2
    )
    if sim.zoom_ratio <= 1.0:
        return 0.0
    return min(1.0, max(0.0, math.log(magnification) / math.log(sim.zoom_ratio)))


def fully_visible(gt: GroundTruth, track: int, frame: int) -> bool:
    """Nothing of the walker hidden in this frame, per the scene's visibility map (a ground
    truth without one counts as visible): whom an operator would pick, or a benchmark start
    on. A walker behind a hedge has an amodal box of mostly hedge."""
    return gt.visibility.get(track, {}).get(frame, 1.0) >= 0.99


def _well_visible(gt: GroundTruth, track: int, frame: int) -> bool:
    """Fully visible, inside the frame, not tiny."""
    x, y, w, h = gt.tracks[track][frame]
    width, height = gt.size
    margin = 0.02 * width
    inside = x >= margin and y >= 0 and x + w <= width - margin and y + h <= height
    return inside and fully_visible(gt, track, frame) and h >= 0.05 * height


def _first_well_visible(gt: GroundTruth, track: int) -> int | None:
    """The first frame in which the walker is well visible, or None if he never is."""
    return next((f for f in sorted(gt.tracks[track]) if _well_visible(gt, track, f)), None)


def first_well_visible(gt: GroundTruth, track: int) -> int:
    """The first frame in which the walker is fully visible, inside the frame and not tiny."""
    start = _first_well_visible(gt, track)
    if start is None:
        raise UsageError(f"--target {track}: the walker is never fully in view")
    return start


def pick_walker(gt: GroundTruth) -> tuple[int, int]:
    """The synthetic scene's walker to follow and the frame to start at: the walker with the
    most frames left after it is first fully in view (ties: the earliest start)."""
    best: tuple[int, int, int] | None = None  # (frames left, -start, -id)
    for tid, frames in gt.tracks.items():
        start = _first_well_visible(gt, tid)
        if start is None:
            continue
        key = (sum(1 for f in frames if f >= start), -start, -tid)
        if best is None or key > best:
            best = key
    if best is None:
        raise UsageError("the scene has no walker fully in view to follow")
    return -best[2], -best[1]


# --- recording ------------------------------------------------------------------------------


@dataclass
class _Recorder:
    """Daemon observer: track.jsonl lines and the zoom-layer timeline."""

    epoch_of: Any  # () -> the camera's epoch (times are seconds since the run started)
    video_frame_of: Any  # index -> video frame
    stream: TextIO | None = None
    keep: int | None = None  # records kept in `tracks` (None: all; the stream gets all)
    tracks: list[dict[str, Any]] = field(default_factory=list)
    zoom_timeline: list[tuple[float, int]] = field(default_factory=lambda: [(0.0, 0)])
    modes: dict[str, int] = field(default_factory=dict)

    def on_track(self, item: TrackItem) -> None:
        r = item.result
        record = {
            "t": round(item.frame.capture_time - self.epoch_of(), 6),
            "frame": item.frame.index,
            "video_frame": self.video_frame_of(item.frame.index),
            "box": None if r is None else [round(v, 2) for v in r.box],
            "state": item.published_state,
            "confidence": None if r is None else round(r.confidence, 4),
            "tracker": item.tracker,
        }
        if item.transitions:
            record["transitions"] = [t.to_dict() for t in item.transitions]
        if self.keep is None or len(self.tracks) < self.keep:
            self.tracks.append(record)
        if self.stream is not None:
            self.stream.write(json.dumps(record, separators=(",", ":")) + "\n")

    def on_decision(self, decision: ControlDecision, now: float, zoom_layer: int) -> None:
        self.modes[decision.mode] = self.modes.get(decision.mode, 0) + 1
        if zoom_layer != self.zoom_timeline[-1][1]:
            self.zoom_timeline.append((round(now - self.epoch_of(), 6), zoom_layer))


@dataclass
class _Rendered:
    t: float
    video_frame: int
    pose: Pose
    index: int = -1  # the camera's frame number (track.jsonl's "frame")


def _line_synced_clock() -> Any:
    """A `VirtualClock` that does not advance while Pelco bytes are inside the kernel's pty.

    A pty hands written bytes to its other end asynchronously, so "every task waits" is not
    enough: the dome could see a command a virtual frame early or late from run to run.
    `settle()` therefore also yields until the dome's end has every byte the link wrote
    (`in_flight`, set once both ends exist). It yields rather than awaiting an event on
    purpose: a waiting task is exactly what lets virtual time advance."""
    import time

    from ptzd.clock import VirtualClock

    class LineSyncedClock(VirtualClock):
        TIMEOUT_S = 5.0

        def __init__(self) -> None:
            super().__init__()
            self.in_flight: Any = lambda: False

        async def settle(self) -> None:
            deadline = time.monotonic() + self.TIMEOUT_S
            await super().settle()
            while self.in_flight():
                if time.monotonic() > deadline:
                    raise TimeoutError(f"Pelco bytes still in flight after {self.TIMEOUT_S} s")
                await asyncio.sleep(0)
                await super().settle()

    return LineSyncedClock()


# --- the run --------------------------------------------------------------------------------


async def run_closed_loop(options: ClosedLoopOptions) -> dict[str, Any]:
    """Run the simulated dome and the daemon together; returns the report."""
    from ptzd.app import Daemon, daemon_detector
    from ptzd.capture import SimFrameSource
    from ptzd.clock import Clock, RealClock
    from ptzd.mqtt.bridge import optional_bridge
    from ptzd.pelco.link import PelcoLink
    from ptzd.sim.camera import Recorder, SimCamera, SourceEnded
    from ptzd.sim.camera_model import CameraModel
    from ptzd.sim.dome import Dome
    from ptzd.sim.endpoint import PtyEndpoint
    from ptzd.sim.sources import open_wide_source
    from ptzd.vision.tracking import make_tracker

    config = options.config
    sim_cfg = config.sim
    if options.acquire and not config.acquisition.enabled:
        raise UsageError("--acquire needs acquisition.enabled = true (the daemon's detector)")
    if options.wide_hfov is not None:
        sim_cfg = sim_cfg.model_copy(update={"wide_hfov": options.wide_hfov})
    try:
        source = open_wide_source(options.spec, gt_path=options.gt_path, loop=options.loop)
    except (OSError, ValueError) as exc:
        raise UsageError(f"cannot open wide source {options.spec!r}: {exc}") from None
    gt = source.ground_truth
    if gt is None:
        raise UsageError(f"{options.spec}: no ground truth; give --gt GT.json --target ID")
    if options.target is not None:
        target = options.target
        if target not in gt.tracks or not gt.tracks[target]:
            raise UsageError(f"--target {target}: no such track in the ground truth")
        first = min(gt.tracks[target])
        if options.gt_path is None:
            # a synthetic scene's walker enters at the wide image's edge or from behind
            # something; like an operator, start on him once he is well in view
            first = first_well_visible(gt, target)
    else:
        target, first = pick_walker(gt)
    frames = gt.tracks[target]
    last = max(frames)
    src_fps = float(source.fps)
    available = (last - first + 1) / src_fps
    duration = min(options.duration, available) if options.duration else available
    count = source.frame_count
    if options.loop:
        if count is None or options.duration is None:
            raise UsageError("--loop needs a wide source of known length and --duration")
        duration = options.duration

    clock: Clock = _line_synced_clock() if options.virtual else RealClock()
    recorder = None
    if options.record is not None:
        recorder = Recorder(options.record)
        recorder.open(ground_truth=True)

    class RangeCamera(SimCamera):
        """Plays the wide source from the target's first ground-truth frame to its last."""

        def video_frame_at(self, index: int) -> int:
            frame = first + math.floor(index * self.source.fps / self.fps + 1e-9)
            if options.loop and count:
                return frame % count
            if frame > last:
                raise SourceEnded(frame)
            return frame

    view_size = (sim_cfg.view_width, sim_cfg.view_height)
    pose0 = pose_towards(
        CameraModel(source.size, sim_cfg.wide_hfov, view_size), frames[first], sim_cfg
    )
    if sim_cfg.start_hfov is not None:
        hfov = min(sim_cfg.zoom_hfov_wide, max(sim_cfg.zoom_hfov_tele, sim_cfg.start_hfov))
        pose0 = replace(pose0, hfov=hfov)
    if sim_cfg.start_pan is not None:
        pose0 = replace(pose0, pan=sim_cfg.start_pan)
    if sim_cfg.start_tilt is not None:
        pose0 = replace(pose0, tilt=sim_cfg.start_tilt)
    dome = Dome(
        sim_cfg,
        start_time=clock.now(),
        pan=pose0.pan,
        tilt=pose0.tilt,
        zoom=zoom_position(sim_cfg, pose0.hfov),
    )
    camera = RangeCamera(source, sim_cfg, clock, recorder=recorder, dome=dome)
    # a looped run keeps per-frame records in memory only for its first pass (the scored
    # one): a day-long run must not grow; the jsonl files still get every frame
    keep_frames = None
    if options.loop and count:
        keep_frames = round((count - first) * camera.fps / src_fps)
    pose0 = dome.pose
    init_box = camera.model.box_to_view(frames[first], pose0)
    if init_box is None:
        raise UsageError(f"target {target} is not visible in the first view")

    rendered: list[_Rendered] = []

    def on_rendered(f: Any) -> None:
        if keep_frames is None or len(rendered) < keep_frames:
            rendered.append(_Rendered(f.t - camera.epoch, f.video_frame, f.pose, f.index))

    camera.listeners.append(on_rendered)
    frame_source = SimFrameSource(
        camera,
        report_pose=sim_cfg.report_pose,
        latency_s=config.capture.latency_s,
        jpeg_quality=sim_cfg.jpeg_quality if sim_cfg.compress_frames else None,
    )
    pty = PtyEndpoint(camera.link, clock)
    track_stream: TextIO | None = None
    try:
        port = pty.open()
        if options.record is not None:
            track_stream = _open_lines(options.record / "track.jsonl")
        serial_cfg = config.serial.model_copy(
            update={"port": port, "address": sim_cfg.address, "baudrate": sim_cfg.baudrate}
        )
        observer = _Recorder(lambda: camera.epoch, camera.video_frame_at, track_stream,
                             keep=keep_frames)  # fmt: skip
        async with (
            PelcoLink(serial_cfg, clock=clock, seed=0) as link,
            optional_bridge(config.mqtt, config.camera.name) as bridge,
        ):
            if options.virtual:
                line = camera.link.counters
                clock.in_flight = lambda: link.counters.bytes_sent > line.bytes  # type: ignore[attr-defined]
            daemon = Daemon(
                config,
                source=frame_source,
                tracker_factory=lambda: make_tracker(config.tracker),
                link=link,
                clock=clock,
                initial_box=None if options.acquire else init_box,
                start_pose=pose0,
                inline_vision=options.virtual,
                observer=observer,
                bridge=bridge,
                detector=daemon_detector(config),
            )
            await _drive(camera, daemon, clock, duration)
            # both ends before closing the link adds its own STOPs (the dome has stopped listening)
            link_frames_sent = link.counters.frames_sent
            frames_received = camera.link.counters.frames
    finally:
        pty.close()
        if recorder is not None:
            recorder.close()
        if track_stream is not None:
            track_stream.close()

    report = build_report(
        rendered=rendered,
        model=camera.model,
        target_frames=frames,
        desired_height=init_box[3],
        tracks=observer.tracks,
        zoom_timeline=observer.zoom_timeline,
        latencies=list(daemon.stats.latencies),
        extra={
            "source": options.spec,
            "target": target,
            "virtual_clock": options.virtual,
            "duration_s": duration,
            "frames_dropped": daemon.stats.frames_dropped,
            "frames_skipped_by_camera": camera.frames_skipped,
            "frames_processed": daemon.stats.frames_processed,
            "commands_sent": daemon.stats.commands_sent,
            "link_frames_sent": link_frames_sent,
            "serial_frames_received": frames_received,
            "bad_checksums": int(camera.link.parser.bad_checksums),
            "stale_stops": daemon.stats.stale_stops,
            "control_modes": observer.modes,
            "acquire": options.acquire,
            "loop": options.loop,
            # seconds from the start to the first frame with a locked target
            "first_lock_s": next(
                (t["t"] for t in observer.tracks if t["state"] == "tracking"), None
            ),
        },
    )
    if options.record is not None:
        (options.record / "report.json").write_text(json.dumps(report, indent=2) + "\n")
        draw_report(report, rendered, options.record / "report.png")
    if options.view is not None:
        write_view(options.view, source, camera.model, rendered, observer.tracks, frames,
                   camera.fps)  # fmt: skip
    return report


_STATE_COLOURS = {"tracking": (0, 200, 0), "occluded": (0, 200, 255), "lost": (0, 0, 255)}


def write_view(
    path: Path,
    source: Any,
    model: CameraModel,
    rendered: Sequence[_Rendered],
    tracks: Sequence[dict[str, Any]],
    target_frames: dict[int, BoxTuple],
    fps: float,
) -> None:
    """The dome's views again from the recorded poses, with the central cell of the 3x3 grid
    (grey), the tracker's box (colour by state) and the target's true centre (white dot)."""
    import cv2
    import numpy as np

    width, height = model.view_size
    path.parent.mkdir(parents=True, exist_ok=True)
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*"mp4v"), fps, (width, height))
    if not writer.isOpened():
        raise UsageError(f"cannot write view video {path}")
    by_frame = {t["frame"]: t for t in tracks}
    track: dict[str, Any] | None = None
    try:
        for frame in rendered:
            view: Any = np.ascontiguousarray(
                model.render(source.read(frame.video_frame), frame.pose)
            )
            if view.ndim == 2:
                view = cv2.cvtColor(view, cv2.COLOR_GRAY2BGR)
            elif view.shape[2] == 4:
                view = cv2.cvtColor(view, cv2.COLOR_BGRA2BGR)
            cell = ((width // 3, height // 3), (2 * width // 3, 2 * height // 3))
            cv2.rectangle(view, *cell, (160, 160, 160), 1)
            track = by_frame.get(frame.index, track)  # a skipped frame shows the last track
            if track is not None and track["box"] is not None:  # None: no target (searching)
                x, y, w, h = (round(v) for v in track["box"])
                colour = _STATE_COLOURS.get(track["state"], (255, 0, 0))
                cv2.rectangle(view, (x, y), (x + w, y + h), colour, 2)
            box = target_frames.get(frame.video_frame)
            if box is not None:
                bx, by, bw, bh = box
                u, v = model.wide_to_view([[bx + bw / 2, by + bh / 2]], frame.pose)[0]
                if math.isfinite(u) and math.isfinite(v):
                    cv2.circle(view, (int(u), int(v)), 3, (255, 255, 255), -1)
            state = track["state"] if track is not None else "-"
            label = f"t {frame.t:5.1f} s  hfov {frame.pose.hfov:5.1f}  {state}"
            cv2.putText(view, label, (8, 20), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1)
            writer.write(view)
    finally:
        writer.release()


async def _drive(camera: Any, daemon: Any, clock: Any, duration: float) -> None:
    """Run daemon and camera; when the camera is done, stop the daemon in order while the
    dome's end of the line keeps listening, so its final STOP reaches the dome too."""
    from ptzd.clock import VirtualClock

    virtual = isinstance(clock, VirtualClock)
    drain_s = 0.2  # > one Pelco frame at 2400 baud plus the dome's reaction time
    async with asyncio.TaskGroup() as group:
        daemon_task = group.create_task(daemon.run(), name="daemon")
        await daemon.ready.wait()
        if virtual:
            await clock.settle()
            camera_task = group.create_task(camera.run(duration), name="sim-camera")
            await clock.run_until(camera.epoch + duration)
            await camera_task
        else:
            await camera.run(duration)
        line = group.create_task(camera.link.run(), name="sim-serial")
        daemon.request_stop()
        if virtual:
            while not daemon_task.done():
                await clock.run_until(clock.now() + 0.05)
        else:
            await daemon_task
        # until the final STOP has left the link and crossed the line (bounded)
        link, deadline = daemon.link, clock.now() + 2.0
        while clock.now() < deadline and (
            not link.idle or camera.link.counters.bytes < link.counters.bytes_sent
        ):
            await (clock.run_until(clock.now() + 0.05) if virtual else asyncio.sleep(0.05))
        await (clock.run_until(clock.now() + drain_s) if virtual else asyncio.sleep(drain_s))
        camera.dome.advance_to(clock.now())
        line.cancel()


# --- report ---------------------------------------------------------------------------------


def in_central_cell(u: float, v: float, width: int, height: int) -> bool:
    """Whether view pixel (u, v) is in the central cell of the view's 3x3 grid: what the
    closed-loop issue calls centred."""
    return abs(u - width / 2) <= width / 6 and abs(v - height / 2) <= height / 6


def build_report(
    *,
    rendered: Sequence[_Rendered],
    model: CameraModel,
    target_frames: dict[int, BoxTuple],
    desired_height: float,
    tracks: Sequence[dict[str, Any]],
    zoom_timeline: Sequence[tuple[float, int]],
    latencies: Sequence[float],
    extra: dict[str, Any],
) -> dict[str, Any]:
    """Centring, in-view, size error, zoom timeline, latency and drops of one run."""
    from ptzd.app import latency_percentiles

    width, height = model.view_size
    scored = centred = in_view = 0
    size_errors: list[float] = []
    per_frame: list[dict[str, Any]] = []
    # what the tracker said of each frame the target was not centred in: a miss while
    # tracking is the control's (or a box on the wrong thing), while occluded the coast's,
    # while lost the search's ("none": the frame was dropped, or its record not kept)
    state_of = {t["frame"]: t["state"] for t in tracks}
    uncentred: Counter[str] = Counter()
    for frame in rendered:
        box = target_frames.get(frame.video_frame)
        if box is None:
            continue
        x, y, w, h = box
        u, v = (float(c) for c in model.wide_to_view([[x + w / 2, y + h / 2]], frame.pose)[0])
        scored += 1
        ok_view = math.isfinite(u) and 0 <= u < width and 0 <= v < height
        ok_centre = ok_view and in_central_cell(u, v, width, height)
        in_view += ok_view
        centred += ok_centre
        if not ok_centre:
            uncentred[state_of.get(frame.index, "none")] += 1
        view_box = model.box_to_view(box, frame.pose)
        size_error = None
        if view_box is not None and ok_view:
            size_error = view_box[3] / desired_height - 1.0
            size_errors.append(abs(size_error))
        per_frame.append(
            {
                "t": round(frame.t, 4),
                "ex": round((u - width / 2) / (width / 2), 4) if math.isfinite(u) else None,
                "ey": round((v - height / 2) / (height / 2), 4) if math.isfinite(v) else None,
                "hfov": round(frame.pose.hfov, 4),
                "size_error": None if size_error is None else round(size_error, 4),
            }
        )
    reversals = _reversal_times(zoom_timeline)
    lost = sum(1 for t in tracks if t["state"] == "lost")
    size_errors.sort()
    return {
        "frames_rendered": len(rendered),
        "frames_scored": scored,
        "centred_fraction": centred / scored if scored else None,
        "in_view_fraction": in_view / scored if scored else None,
        "uncentred_by_state": dict(sorted(uncentred.items())),
        "size_error_median": size_errors[len(size_errors) // 2] if size_errors else None,
        "size_error_mean": sum(size_errors) / len(size_errors) if size_errors else None,
        "zoom_layer_timeline": [[t, layer] for t, layer in zoom_timeline],
        "zoom_reversals": len(reversals),
        "max_reversals_per_10s": _max_in_window(reversals, REVERSAL_WINDOW_S),
        "latency_ms": latency_percentiles(list(latencies)),
        "track_frames": len(tracks),
        "track_lost_frames": lost,
        **extra,
        "per_frame": per_frame,
    }


def _open_lines(path: Path) -> TextIO:
    """A line-buffered text file (closed by the caller)."""
    return open(path, "w", buffering=1)


def _reversal_times(timeline: Sequence[tuple[float, int]]) -> list[float]:
    out: list[float] = []
    last_direction = 0
    for (_, a), (t, b) in itertools.pairwise(timeline):
        direction = 1 if b > a else -1
        if last_direction and direction != last_direction:
            out.append(t)
        last_direction = direction
    return out


def _max_in_window(times: Sequence[float], window: float) -> int:
    best = 0
    start = 0
    for end, t in enumerate(times):
        while t - times[start] >= window:
            start += 1
        best = max(best, end - start + 1)
    return best


def summary(report: dict[str, Any]) -> dict[str, Any]:
    """The report without its per-frame series (what the CLI prints)."""
    return {k: v for k, v in report.items() if k not in ("per_frame", "zoom_layer_timeline")}


def draw_report(report: dict[str, Any], rendered: Sequence[_Rendered], path: Path) -> None:
    """report.png: target offset, size error, FOV and zoom layer over time (cv2 only)."""
    import cv2
    import numpy as np

    series = report["per_frame"]
    width, panel_h, margin = 1000, 160, 40
    panels = 4
    image = np.full((panels * panel_h + margin, width, 3), 255, np.uint8)
    duration = max((f["t"] for f in series), default=1.0) or 1.0

    def x_of(t: float) -> int:
        return int(margin + (width - 2 * margin) * t / duration)

    def panel(i: int, title: str, lo: float, hi: float) -> Any:
        top = i * panel_h + 20
        bottom = top + panel_h - 40
        cv2.rectangle(image, (margin, top), (width - margin, bottom), (200, 200, 200), 1)
        cv2.putText(image, title, (margin, top - 5), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0, 0, 0), 1)

        def y_of(v: float) -> int:
            v = min(hi, max(lo, v))
            return int(bottom - (bottom - top) * (v - lo) / (hi - lo))

        return y_of

    def plot(
        y_of: Any, points: list[tuple[float, float | None]], colour: tuple[int, int, int]
    ) -> None:
        previous = None
        for t, v in points:
            if v is None:
                previous = None
                continue
            p = (x_of(t), y_of(v))
            if previous is not None:
                cv2.line(image, previous, p, colour, 1, cv2.LINE_AA)
            previous = p

    y = panel(0, "target offset / half frame (ex blue, ey red); central cell = +-1/3", -1.0, 1.0)
    for level in (-1 / 3, 1 / 3):
        cv2.line(image, (margin, y(level)), (width - margin, y(level)), (0, 160, 0), 1)
    plot(y, [(f["t"], f["ex"]) for f in series], (255, 0, 0))
    plot(y, [(f["t"], f["ey"]) for f in series], (0, 0, 255))
    y = panel(1, "size error (view height / desired - 1)", -1.0, 1.0)
    cv2.line(image, (margin, y(0)), (width - margin, y(0)), (0, 160, 0), 1)
    plot(y, [(f["t"], f["size_error"]) for f in series], (120, 0, 120))
    hfovs = [f["hfov"] for f in series] or [1.0]
    y = panel(2, "horizontal FOV (deg)", 0.0, max(hfovs) * 1.1)
    plot(y, [(f["t"], f["hfov"]) for f in series], (0, 100, 200))
    layers = [layer for _, layer in report["zoom_layer_timeline"]]
    lo, hi = min(layers) - 1, max(layers) + 1
    y = panel(3, "zoom layer", float(lo), float(hi))
    steps: list[tuple[float, float | None]] = []
    for (t, layer), nxt in zip(
        report["zoom_layer_timeline"],
        [*report["zoom_layer_timeline"][1:], [duration, None]],
        strict=True,
    ):
        steps += [(t, float(layer)), (nxt[0], float(layer))]
    plot(y, steps, (0, 0, 0))

    def fmt(value: object, spec: str) -> str:
        return "n/a" if value is None else format(value, spec)

    text = (
        f"centred {fmt(report['centred_fraction'], '.3f')}  "
        f"in view {fmt(report['in_view_fraction'], '.3f')}  "
        f"latency p50/p99 {fmt(report['latency_ms']['p50_ms'], '.1f')}/"
        f"{fmt(report['latency_ms']['p99_ms'], '.1f')} ms  "
        f"dropped {report['frames_dropped']}  reversals {report['zoom_reversals']}  "
        f"duration {duration:.1f} s"
    )
    cv2.putText(
        image, text[:150], (margin, panels * panel_h + 25), cv2.FONT_HERSHEY_SIMPLEX, 0.45,
        (0, 0, 0), 1,
    )  # fmt: skip
    if not cv2.imwrite(str(path), image):
        raise OSError(f"cannot write {path}")
