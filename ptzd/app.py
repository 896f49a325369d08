"""The daemon: capture -> vision -> control -> serial, one supervised asyncio TaskGroup.

Tasks (named as below) joined by single-slot latest-value mailboxes (`ptzd.mailbox`):

- ``capture``: frames from a `FrameSource` (cv2.VideoCapture in a thread, or the simulator)
  into the frame mailbox. A frame the vision worker has not taken yet is replaced, never
  queued; replacements are counted as dropped frames.
- ``vision``: the tracker, off the event loop in its own thread, on the latest frame, with
  the dome's motion since the previous frame as ego-motion (and zoom as `rescale`). With a
  detector (acquisition enabled) the same thread then runs the detector and the acquisition
  state machine, which locks new targets, re-identifies lost ones and gives up (docs/daemon.md).
  Each result goes to the track mailbox with the frame's capture time.
- ``control``: at a fixed rate and at once on every new track, `PtzController` turns the
  latest track into a command. A track older than `control.max_track_age_s` is never acted
  on: the dome gets STOP.
- ``serial``: writes commands to the Pelco link. STOP first thing, STOP last thing.
- ``mqtt`` (with a bridge): publishes tracks and state, takes select/autotrack/manual commands.
- ``watchdog`` and ``status`` (under systemd, `notifier` enabled): ``READY=1`` once the first
  frame arrived (the serial link is open before the daemon starts), ``STATUS=`` every
  `status_interval_s`, ``WATCHDOG=1`` only while frames and control ticks are fresh (so a
  wedged capture gets the service restarted), ``STOPPING=1`` when shutdown begins.

Shutdown (`request_stop()`, SIGINT/SIGTERM in `ptzd run`): capture is cancelled and closes
the frame mailbox; vision finishes its frame and closes the track mailbox; control sends STOP
and closes the command mailbox; serial writes what is left (ending with STOP) and returns.
On any crash the TaskGroup cancels the rest, and STOP is still written on the way out.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import inspect
import math
import time
from collections import deque
from collections.abc import Callable, Mapping
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol, TypeVar

import numpy as np
import numpy.typing as npt

from ptzd import heap
from ptzd.capture import FrameItem, FrameSource
from ptzd.clock import Clock
from ptzd.config import Config
from ptzd.control.controller import STOP, ControlDecision, PtzController, TrackInput
from ptzd.control.egomotion import DomeEstimate, focal_ratio, view_homography
from ptzd.control.zoom import Box
from ptzd.logs import get_logger
from ptzd.mailbox import Mailbox, MailboxClosedError
from ptzd.pelco.codec import Command, Motion, Preset, PresetAction, Zoom
from ptzd.sdnotify import Heartbeats, Notifier, Watchdog
from ptzd.sim.camera_model import Pose
from ptzd.vision.acquisition import AcqState, Acquirer, Decision, Transition
from ptzd.vision.acquisition import TrackResult as AcqTrack
from ptzd.vision.auto import running_kind
from ptzd.vision.detect.types import Detector
from ptzd.vision.particle_filter import apply_homography
from ptzd.vision.tracking import Tracker, TrackResult, TrackState, centre_box

if TYPE_CHECKING:
    from ptzd.mqtt.bridge import MqttBridge
    from ptzd.mqtt.messages import Command as MqttCommand

_log = get_logger("daemon")

T = TypeVar("T")
BoxTuple = tuple[float, float, float, float]
# the latest frame-to-command latencies kept for percentiles: ~7 minutes at 25 fps, 0.3 MB.
# (100_000 made the RSS of a long run climb for over an hour before the deque was full.)
LATENCY_SAMPLES = 10_000
# the watchdog is fed only while a frame and a control tick came within this long
HEALTH_MAX_AGE_S = 2.0
STATUS_INTERVAL_S = 5.0
# poses of the frames the vision worker took, for a select drawn on an older frame: 10 s at
# 30 fps; and how near in time a remembered frame must be to the one the box was drawn on
POSE_MEMORY = 300
DRAWN_FRAME_MATCH_S = 0.25
# the frames themselves, for the last `capture.select_history_s` (and at most this many): a
# box drawn on one of them starts the tracker there, and it follows the target to the
# newest frame. An operator's box reaches us 0.1-0.3 s after the picture he drew it on; a
# walker has moved on by then, and a model learnt from the box put on the newest frame
# holds the ground he left (the soak's walkers: replayed centred 0.995 -> 0.530 with the
# box 4 frames late; docs/mqtt.md).
HISTORY_MAX_FRAMES = 150


class CommandLink(Protocol):
    """Where commands go: the Pelco link (`ptzd.pelco.link.PelcoLink`) or a test double.
    `send` may be a coroutine function or a plain one."""

    def send(self, command: Command) -> object: ...


async def send_command(link: CommandLink, command: Command) -> None:
    """`link.send(command)`, awaited if it returns an awaitable."""
    result = link.send(command)
    if inspect.isawaitable(result):
        await result


@dataclass(frozen=True, slots=True)
class TrackItem:
    """One processed frame: the tracker's result (None: no target) and the frame."""

    result: TrackResult | None
    frame: FrameItem
    pose: Pose  # the dome pose at capture (reported by the source, else dead-reckoned)
    velocity: tuple[float, float]  # px/s, the target's own motion (ego-motion removed)
    acquired: BoxTuple | None = None  # set on the first result of a newly selected target
    generation: int = 0  # the target selection this track belongs to
    # with acquisition: its state (searching, tracking, occluded, lost, returning_home) and
    # the transitions made on this frame
    state: str | None = None
    transitions: tuple[Transition, ...] = ()
    # the likelihood that made `result` (`auto`: day or night); None without a result
    tracker: str | None = None

    @property
    def published_state(self) -> str:
        """The state on MQTT and in STATUS=: searching, tracking, occluded or lost."""
        if self.state is not None:
            return "searching" if self.state == AcqState.RETURNING_HOME else self.state
        return "searching" if self.result is None else str(self.result.state)


@dataclass(frozen=True, slots=True)
class CommandBatch:
    """Commands to write, with the wall stamp of the frame they answer (for latency)."""

    commands: tuple[Command, ...]
    frame_wall_time: float | None = None
    source: str = "auto"  # "manual" for MQTT moves: reported on ptz/state once written


@dataclass
class DaemonStats:
    """Counters and latency samples; read them any time."""

    frames_captured: int = 0
    frames_processed: int = 0
    frames_dropped: int = 0
    tracks_dropped: int = 0
    commands_sent: int = 0
    stale_stops: int = 0
    zoom_steps: int = 0
    heap_trims: int = 0  # malloc's free pages handed back (`ptzd.heap`)
    # seconds from frame capture to its command being written (or confirmed unchanged), the
    # latest LATENCY_SAMPLES of them
    latencies: deque[float] = field(default_factory=lambda: deque(maxlen=LATENCY_SAMPLES))


class DaemonObserver(Protocol):
    """Optional hooks for recorders and tests (called on the event loop)."""

    def on_track(self, item: TrackItem) -> None: ...

    def on_decision(self, decision: ControlDecision, now: float, zoom_layer: int) -> None: ...


class Daemon:
    """The pipeline, assembled from its parts so the simulator and tests can build it.

    `inline_vision` runs the tracker on the event loop instead of a thread: slower, but every
    step then happens in a fixed order, which the virtual-clock simulation needs.
    """

    def __init__(
        self,
        config: Config,
        *,
        source: FrameSource,
        tracker_factory: Callable[[], Tracker],
        link: CommandLink,
        clock: Clock,
        initial_box: BoxTuple | None = None,
        start_pose: Pose | None = None,
        inline_vision: bool = False,
        observer: DaemonObserver | None = None,
        bridge: MqttBridge | None = None,
        detector: Detector | None = None,
        notifier: Notifier | None = None,
        watchdog_environ: Mapping[str, str] | None = None,
        health_max_age_s: float = HEALTH_MAX_AGE_S,
        status_interval_s: float = STATUS_INTERVAL_S,
        heap_trim_interval_s: float = heap.TRIM_INTERVAL_S,
    ) -> None:
        self.config = config
        self.source = source
        self.tracker_factory = tracker_factory
        self.link = link
        self.clock = clock
        self.inline_vision = inline_vision
        self.observer = observer
        self.bridge = bridge
        # with a detector (and `acquisition.enabled`) the daemon finds people by itself
        self.detector = detector if config.acquisition.enabled else None
        self.acquirer: Acquirer | None = None  # built on the first frame (its size)
        self._acquiring = True  # acquisition runs (not paused by a manual command)
        self._home_requested = False  # acquisition gave up: control sends the home preset
        self.notifier = notifier
        self.heartbeats = Heartbeats(("frame", "control"), clock=clock)
        self.health_max_age_s = health_max_age_s
        self.status_interval_s = status_interval_s
        self.heap_trim_interval_s = heap_trim_interval_s
        self._watchdog_environ = watchdog_environ  # None: os.environ (WATCHDOG_USEC)
        self._track_state = "waiting"  # for STATUS=
        self._stopping_sent = False
        self.stats = DaemonStats()
        self.frames: Mailbox[FrameItem] = Mailbox("frames")
        self.tracks: Mailbox[TrackItem] = Mailbox("tracks")
        self.commands: Mailbox[CommandBatch] = Mailbox("commands")
        self.controller: PtzController | None = None  # built on the first frame (its size)
        ctl = config.control
        self.estimate = DomeEstimate(
            ctl.dome,
            ctl.zoom.log_rate,
            start_pose or Pose(0.0, 0.0, ctl.reference_hfov),
            clock.now(),
        )
        self._pending_box: BoxTuple | None = initial_box
        self._pending_drawn_at: float | None = None  # capture time of the box's frame
        self._poses: deque[tuple[float, Pose]] = deque(maxlen=POSE_MEMORY)
        self._recent: deque[tuple[FrameItem, Pose]] = deque(maxlen=HISTORY_MAX_FRAMES)
        self._drop_target = False
        self._generation = 0  # bumped by select/release: older tracks are ignored
        self._manual = False  # a manual MQTT command is in force: control sends nothing
        self._zoom_layer = 0
        self._last_motion: Motion | None = None
        self._last_sent = -math.inf
        self._frame_time: float | None = None  # capture time of the newest track item
        self._capture_task: asyncio.Task[None] | None = None
        self._mqtt_task: asyncio.Task[None] | None = None
        self._aux_tasks: list[asyncio.Task[None]] = []  # end with the pipeline (mqtt, systemd)
        self._executor: ThreadPoolExecutor | None = None
        self._stop_requested = False
        self._final_stop_sent = False
        self._fps = 0.0
        # set once the vision worker waits for its first frame (tracker built): capture, and
        # a simulator driving this daemon, start only then so the initial box meets the frame
        # it was drawn on
        self.ready = asyncio.Event()

    # --- API -----------------------------------------------------------------------------

    def select(self, box: BoxTuple, drawn_at: float | None = None) -> None:
        """Track the target in `box` (x, y, w, h, view pixels) from the next frame on.

        `drawn_at`: the capture time (daemon clock) of the frame the box was drawn on; the
        box is then moved by the camera's motion from that frame to the next (None: the
        box is taken as drawn on the next frame)."""
        x, y, w, h = box
        if not (w > 0 and h > 0 and all(math.isfinite(v) for v in box)):
            raise ValueError(f"select box must be finite with positive size, got {box}")
        self._pending_box = (float(x), float(y), float(w), float(h))
        self._pending_drawn_at = drawn_at
        self._drop_target = False
        self._manual = False
        self._generation += 1

    def release(self) -> None:
        """Stop tracking (the dome stops and stays)."""
        self._pending_box = None
        self._drop_target = True
        self._generation += 1

    def request_stop(self) -> None:
        """Begin the orderly shutdown (safe to call more than once)."""
        self._stop_requested = True
        self._notify_stopping()
        if self._capture_task is not None:
            self._capture_task.cancel()

    # --- run -----------------------------------------------------------------------------

    async def run(self) -> None:
        """Run until the source ends or `request_stop()`; the dome is left stopped."""
        self._executor = None if self.inline_vision else ThreadPoolExecutor(1, "vision")
        try:
            async with asyncio.TaskGroup() as group:
                self._capture_task = group.create_task(self._capture(), name="capture")
                if self._stop_requested:
                    self._capture_task.cancel()
                group.create_task(self._vision(), name="vision")
                group.create_task(self._control(), name="control")
                group.create_task(self._serial(), name="serial")
                if self.bridge is not None:
                    self._mqtt_task = group.create_task(self._mqtt(self.bridge), name="mqtt")
                    self._aux_tasks.append(self._mqtt_task)
                if self.notifier is not None and self.notifier.enabled:
                    self._start_systemd_tasks(group, self.notifier)
        finally:
            self._notify_stopping()
            self.frames.close()
            self.tracks.close()
            self.commands.close()
            if self._executor is not None:
                self._executor.shutdown(wait=False, cancel_futures=True)
            await self._send_final_stop()
            self.stats.frames_dropped = self.frames.dropped
            self.stats.tracks_dropped = self.tracks.dropped
            _log.info(
                "daemon_stopped",
                frames=self.stats.frames_captured,
                processed=self.stats.frames_processed,
                dropped=self.stats.frames_dropped,
                commands=self.stats.commands_sent,
            )

    async def _send_final_stop(self) -> None:
        if self._final_stop_sent:
            return
        try:
            await self._write(STOP, "auto")
            self._final_stop_sent = True
        except Exception as exc:  # the link itself failed: nothing more we can do
            _log.error("final_stop_failed", error=repr(exc))

    # --- systemd -------------------------------------------------------------------------

    def healthy(self) -> bool:
        """Frames arrive and the control loop ticks (the watchdog's predicate)."""
        return self.heartbeats.fresh(self.health_max_age_s)

    def status_text(self) -> str:
        """One line for systemd's STATUS= (shown by `systemctl status`)."""
        stale = self.heartbeats.stale(self.health_max_age_s)
        state = "manual" if self._manual else self._track_state
        text = (
            f"{state}; {self._fps:.1f} fps; frames {self.stats.frames_captured}, "
            f"dropped {self.frames.dropped}; zoom layer {self._zoom_layer}"
        )
        return f"{text}; stalled: {', '.join(stale)}" if stale else text

    def _start_systemd_tasks(self, group: asyncio.TaskGroup, notifier: Notifier) -> None:
        dog = Watchdog.from_environ(
            notifier, self.healthy, environ=self._watchdog_environ, clock=self.clock
        )
        if dog is not None:
            self._aux_tasks.append(group.create_task(dog.run(), name="watchdog"))
        self._aux_tasks.append(group.create_task(self._status(notifier), name="status"))

    async def _status(self, notifier: Notifier) -> None:
        last_count, last_time = self.stats.frames_captured, self.clock.now()
        while True:
            await self.clock.sleep(self.status_interval_s)
            now = self.clock.now()
            count = self.stats.frames_captured
            self._fps = (count - last_count) / (now - last_time) if now > last_time else 0.0
            last_count, last_time = count, now
            notifier.status(self.status_text())

    def _notify_ready(self) -> None:
        if self.notifier is not None:
            self.notifier.ready(status=f"{self._track_state}; first frame arrived")
            _log.info("ready", systemd=self.notifier.enabled)

    def _notify_stopping(self) -> None:
        if self.notifier is not None and not self._stopping_sent:
            self._stopping_sent = True
            self.notifier.stopping(status="stopping: leaving the dome stopped")

    # --- capture -------------------------------------------------------------------------

    async def _capture(self) -> None:
        try:
            await self.ready.wait()
            async for frame in self.source.frames():
                self.stats.frames_captured += 1
                self.heartbeats.beat("frame")
                self.frames.put(frame)
                self.stats.frames_dropped = self.frames.dropped
                if self.stats.frames_captured == 1:
                    self._notify_ready()
        finally:
            self.frames.close()

    # --- vision --------------------------------------------------------------------------

    async def _blocking(self, fn: Callable[..., T], *args: Any) -> T:
        if self._executor is None:
            return fn(*args)
        return await asyncio.get_running_loop().run_in_executor(self._executor, fn, *args)

    def _pose_at(self, frame: FrameItem) -> Pose:
        if frame.pose is not None:
            return frame.pose
        # (the frame may be older than commands sent since: the pose when it was taken)
        return self.estimate.pose_at(frame.capture_time)

    async def _vision(self) -> None:
        tracker: Tracker | None = None  # `own` while there is a target, else None
        generation = self._generation
        previous: tuple[FrameItem, Pose] | None = None
        # One tracker for the camera, initialised again on every new target rather than
        # built anew: a tracker's frame-sized buffers (its motion map: megabytes at 640x480)
        # allocated per lock, a lock every few seconds for months, fragment the heap.
        # The first is built before the first frame (imports, allocations) when there is an
        # initial box: the frame it was drawn on must not be dropped while we get ready.
        own: Tracker | None = None
        if self._pending_box is not None:
            own = await self._blocking(self.tracker_factory)
        self.ready.set()
        next_trim = self.clock.now() + self.heap_trim_interval_s
        try:
            while True:
                if self.clock.now() >= next_trim:  # between frames, on the vision thread
                    await self._blocking(heap.trim)
                    self.stats.heap_trims += 1
                    next_trim = self.clock.now() + self.heap_trim_interval_s
                try:
                    frame = await self.frames.get()
                except MailboxClosedError:
                    return
                pose = self._pose_at(frame)
                self._poses.append((frame.capture_time, pose))
                self._remember(frame, pose)
                if self.detector is not None and self.acquirer is None:
                    self.acquirer = Acquirer(self.config.acquisition, frame.size)
                if self._drop_target:
                    tracker, previous, self._drop_target = None, None, False
                    if self.acquirer is not None:
                        self.acquirer.reset(frame.capture_time)
                # a manual command (or autotrack OFF) pauses acquisition too; it resumes from
                # scratch, the dome having been moved by hand meanwhile (and before a select
                # that ends the pause is applied, so the selected target survives)
                auto = self.acquirer is not None and not self._manual
                if self.acquirer is not None and auto != self._acquiring:
                    self._acquiring = auto
                    if auto and self.detector is not None:
                        self.detector.reset()
                        self.acquirer.reset(frame.capture_time)
                if self._pending_box is not None:
                    generation = self._generation
                    tracker = own = own or self.tracker_factory()
                    since = self._frames_since(self._pending_drawn_at, frame)
                    result: TrackResult | None
                    if since:  # drawn on a remembered frame: start there, catch up to now
                        result = await self._blocking(
                            self._catch_up, tracker, self._pending_box, since
                        )
                        box = result.box
                    else:
                        box = self._drawn_box_now(
                            self._pending_box, self._pending_drawn_at, frame, pose
                        )
                        await self._blocking(tracker.init, frame.image, box)
                        result = TrackResult(box, TrackState.TRACKING, 1.0, (0, 0))
                    self._pending_box = None
                    decision: Decision | None = None
                    if self.acquirer is not None:
                        decision = self.acquirer.select(frame.capture_time, box)
                    self._publish(_track_item(result, frame, pose, (0.0, 0.0), box, generation,
                                              decision, self._kind_of(tracker)))  # fmt: skip
                    previous = (frame, pose)
                    continue
                if not auto and (tracker is None or previous is None):
                    continue
                before = previous[1] if previous is not None else pose
                result = None
                if tracker is not None:
                    result = await self._blocking(self._track_step, tracker, frame, pose, before)
                decision = None
                acquired: BoxTuple | None = None
                if auto and self.acquirer is not None:
                    decision = await self._blocking(
                        self._acquire_step, frame, pose, before, result, tracker
                    )
                    if decision.lock_box is not None:  # a new target, or the old one re-found
                        box = decision.lock_box
                        tracker = own = own or self.tracker_factory()
                        await self._blocking(tracker.init, frame.image, box)
                        result = TrackResult(box, TrackState.TRACKING, 1.0, (0.0, 0.0))
                        if not _reidentified(decision):  # same person: same id, same size
                            acquired = box
                            self._generation += 1
                            generation = self._generation
                    elif decision.state in (AcqState.SEARCHING, AcqState.RETURNING_HOME):
                        tracker, result = None, None  # given up (or dropped as static)
                    if decision.go_home:
                        self._home_requested = True  # for control; survives a replaced track
                velocity = (0.0, 0.0)
                if result is not None and previous is not None:
                    dt = frame.capture_time - previous[0].capture_time
                    vx, vy = result.velocity
                    velocity = (vx / dt, vy / dt) if dt > 0 else (0.0, 0.0)
                kind = self._kind_of(tracker)
                self._publish(
                    _track_item(result, frame, pose, velocity, acquired, generation, decision, kind)
                )
                previous = (frame, pose)
        finally:
            self.tracks.close()

    def _remember(self, frame: FrameItem, pose: Pose) -> None:
        """Keep `frame` for a box drawn on it; forget those older than
        `capture.select_history_s`, and all of another size."""
        keep_s = self.config.capture.select_history_s
        recent = self._recent
        if recent and (keep_s == 0 or recent[-1][0].size != frame.size):
            recent.clear()
        if keep_s == 0:
            return
        recent.append((frame, pose))
        while recent[0][0].capture_time < frame.capture_time - keep_s:
            recent.popleft()

    def _frames_since(
        self, drawn_at: float | None, frame: FrameItem
    ) -> list[tuple[FrameItem, Pose]]:
        """The remembered frames from the one captured at `drawn_at` to `frame` (the
        newest), if that one is remembered and older than `frame`; else none."""
        if drawn_at is None or len(self._recent) < 2:
            return []
        oldest, second = self._recent[0][0].capture_time, self._recent[1][0].capture_time
        if drawn_at < oldest - (second - oldest):
            return []  # drawn before the frames kept: moved by the dome's motion instead
        times = [abs(item.capture_time - drawn_at) for item, _ in self._recent]
        first = times.index(min(times))
        if times[first] > DRAWN_FRAME_MATCH_S or self._recent[first][0] is frame:
            return []
        return list(self._recent)[first:]

    def _catch_up(
        self, tracker: Tracker, box: BoxTuple, frames: list[tuple[FrameItem, Pose]]
    ) -> TrackResult:
        """Start `tracker` on `box` in the first of `frames` and follow the target through
        the rest: its result on the last."""
        (first, before), *rest = frames
        tracker.init(first.image, box)
        result = TrackResult(box, TrackState.TRACKING, 1.0, (0.0, 0.0))
        for frame, pose in rest:
            result = self._track_step(tracker, frame, pose, before)
            before = pose
        return result

    def _kind_of(self, tracker: Tracker | None) -> str | None:
        return running_kind(tracker, self.config.tracker.kind)

    def _drawn_box_now(
        self, box: BoxTuple, drawn_at: float | None, frame: FrameItem, pose: Pose
    ) -> BoxTuple:
        """`box`, drawn on the frame captured at `drawn_at`, where the camera's motion since
        puts it in `frame` (taken at `pose`). An operator draws on a picture a
        little old; with the dome turning, the same pixels of the newest frame show
        something beside the person (the soak's operator, before it waited for a still
        picture: 20 px beside a 19 px wide walker)."""
        if drawn_at is None:
            return box
        then_time, then = min(self._poses, key=lambda item: abs(item[0] - drawn_at))
        if abs(then_time - drawn_at) > DRAWN_FRAME_MATCH_S:
            _log.warning("select_not_moved", reason="no remembered frame near its ts",
                         age_s=round(frame.capture_time - drawn_at, 3),
                         remembered_s=round(frame.capture_time - self._poses[0][0], 3))  # fmt: skip
            return box
        if then == pose:
            return box
        return _move_box(view_homography(frame.size, then, pose), box)

    def _acquire_step(
        self,
        frame: FrameItem,
        pose: Pose,
        before: Pose,
        result: TrackResult | None,
        tracker: Tracker | None,
    ) -> Decision:
        """Detection (when it can run) and the acquisition state machine for one frame.

        The background model needs a still camera: any change of pose between two frames is
        a move, and the detector is told so (it resets and learns again once still); while
        the camera moves only a detector that works on moving views reports anything.
        """
        assert self.detector is not None and self.acquirer is not None
        moving = (pose.pan, pose.tilt, pose.hfov) != (before.pan, before.tilt, before.hfov)
        detections = self.detector.detect(frame.image, camera_moving=moving)
        ran = not moving or self.config.detector.kind == "hog"
        ran = ran or self.config.detector.when_moving == "hog"
        track = None
        if result is not None:  # a tracker that gave up (LOST) reports no box
            box = None if result.state is TrackState.LOST else result.box
            track = AcqTrack(box, occluded=result.state is TrackState.OCCLUDED)
        resembles = None
        if tracker is not None:
            resembles = functools.partial(tracker.resembles, frame.image)
        image_motion = None
        if moving:
            image_motion = functools.partial(_move_box, view_homography(frame.size, before, pose))
        return self.acquirer.update(
            frame.capture_time,
            detections if ran else None,
            track,
            camera_moving=moving,
            resembles=resembles,
            image_motion=image_motion,
        )

    @staticmethod
    def _track_step(tracker: Tracker, frame: FrameItem, pose: Pose, before: Pose) -> TrackResult:
        """Zoom as `rescale` about the centre, then the rotation (at the new FOV) as ego-motion.

        K_b R_bᵀ R_a K_a⁻¹ = (R at the new FOV) · (zoom about the centre), so this order is exact.
        """
        width, height = frame.size
        factor = focal_ratio(before.hfov, pose.hfov)
        if abs(factor - 1.0) > 1e-9:
            tracker.rescale(factor, (width / 2, height / 2))
        ego = None
        if (before.pan, before.tilt) != (pose.pan, pose.tilt):
            ego = view_homography(frame.size, Pose(before.pan, before.tilt, pose.hfov), pose)
        return tracker.update(frame.image, ego)

    def _publish(self, item: TrackItem) -> None:
        self.stats.frames_processed += 1
        self._track_state = item.published_state
        if self.observer is not None:
            self.observer.on_track(item)
        if self.bridge is not None:
            self._publish_mqtt(self.bridge, item)
        self.tracks.put(item)

    def _publish_mqtt(self, bridge: MqttBridge, item: TrackItem) -> None:
        from ptzd.mqtt.messages import TrackMessage

        r = item.result
        age = self.clock.now() - item.frame.capture_time
        bridge.publish_track(
            TrackMessage(
                ts=time.time() - age,
                state=item.published_state,
                id=item.generation,  # one id per target selection
                frame_size=item.frame.size,
                bbox=None if r is None else r.box,
                confidence=None if r is None else r.confidence,
                velocity=None if r is None else item.velocity,
                transitions=tuple(t.to_dict() for t in item.transitions),
                tracker=item.tracker,
            )
        )

    # --- control -------------------------------------------------------------------------

    async def _next_track(self, deadline: float) -> TrackItem | None:
        """The next track if one arrives before `deadline` (clock time), else None."""
        item = self.tracks.get_nowait()
        if item is not None:
            return item
        if self.tracks.closed:
            raise MailboxClosedError(self.tracks.name)
        delay = deadline - self.clock.now()
        if delay <= 0:
            return None
        ready = asyncio.ensure_future(self.tracks.ready())
        timer = asyncio.ensure_future(self.clock.sleep(delay))
        try:
            await asyncio.wait({ready, timer}, return_when=asyncio.FIRST_COMPLETED)
        finally:
            ready.cancel()
            timer.cancel()
        item = self.tracks.get_nowait()
        if item is None and self.tracks.closed:
            raise MailboxClosedError(self.tracks.name)
        return item

    async def _control(self) -> None:
        ctl = self.config.control
        period = 1.0 / ctl.rate_hz
        latest: TrackItem | None = None
        next_tick = self.clock.now() + period
        try:
            while True:
                try:
                    fresh = await self._next_track(next_tick)
                except MailboxClosedError:
                    return
                now = self.clock.now()
                self.heartbeats.beat("control")
                if fresh is None:
                    next_tick = max(next_tick + period, now)
                else:
                    latest = fresh
                    self._frame_time = fresh.frame.capture_time
                    if self.controller is None:
                        self.controller = PtzController(ctl, fresh.frame.size)
                    if fresh.acquired is not None:
                        self.controller.acquire(Box(*fresh.acquired))
                if latest is not None and latest.generation != self._generation:
                    latest = None  # released or replaced since
                self._control_step(latest, fresh, now)
        finally:
            if not self.commands.closed:
                self._queue((STOP,), None)
            self.commands.close()

    def _control_step(self, latest: TrackItem | None, fresh: TrackItem | None, now: float) -> None:
        if latest is not None and latest.frame.pose is not None:
            self.estimate.reset(latest.frame.pose, latest.frame.capture_time)
        pose = self.estimate.advance_to(now)
        if self.controller is None:
            decision = ControlDecision(STOP, "idle")
        else:
            decision = self.controller.update(
                _track_input(latest), now, pose.hfov, self._frame_time
            )
        if decision.mode == "stale" and self._last_motion != STOP:
            self.stats.stale_stops += 1
        if self._manual and latest is None:
            # a manual move is in force and there is no target: keep it (and the link's
            # dead-man) alive, nothing else
            moving = self._last_motion is not None and not self._last_motion.is_stop
            if moving and now - self._last_sent >= self.config.control.refresh_s:
                assert self._last_motion is not None
                self._last_sent = now
                self._queue((self._last_motion,), None, "manual")
            return
        if decision.zoom_step is not None:
            self.stats.zoom_steps += 1
            self._zoom_layer = decision.zoom_step.layer
            if self.bridge is not None:
                self.bridge.set_zoom_layer(decision.zoom_step.layer)
            _log.info(
                "zoom_step",
                direction=decision.zoom_step.direction.name,
                layer=decision.zoom_step.layer,
                factor=round(decision.zoom_step.factor, 3),
                reason=decision.zoom_step.reason,
            )
        if self.observer is not None:
            layer = self.controller.zoom_layer if self.controller is not None else 0
            self.observer.on_decision(decision, now, layer)
        commands: list[Command] = []
        if decision.preset is not None:
            commands.append(decision.preset)
        elif self._home_requested and self.controller is not None:
            self._home_requested = False
            home = self.controller.go_home(now)  # acquisition gave up on the target
            if home is not None:
                commands.append(home)
        motion = decision.motion
        if motion != self._last_motion or now - self._last_sent >= self.config.control.refresh_s:
            commands.append(motion)
            self._last_motion = motion
            self._last_sent = now
            self.estimate.command(motion.pan, motion.tilt, int(motion.zoom), now)
        wall = fresh.frame.wall_time if fresh is not None and fresh.frame.wall_time else None
        if commands:
            self._queue(tuple(commands), wall)
        elif wall is not None:  # decided, and the command in force is already right
            self.stats.latencies.append(time.perf_counter() - wall)

    def _queue(
        self, commands: tuple[Command, ...], wall: float | None, source: str = "auto"
    ) -> None:
        """Replace any unsent batch, but keep its non-motion commands (presets) in front."""
        pending = self.commands.get_nowait()
        if pending is not None:
            kept = tuple(c for c in pending.commands if not isinstance(c, Motion))
            commands = kept + commands
            wall = pending.frame_wall_time if wall is None else wall
        self.commands.put(CommandBatch(commands, wall, source))

    # --- mqtt ----------------------------------------------------------------------------

    async def _mqtt(self, bridge: MqttBridge) -> None:
        bridge.set_autotrack(True)
        bridge.set_zoom_layer(self._zoom_layer)
        async for command in bridge.commands():
            if self.commands.closed:
                return
            self.handle_command(command)

    def handle_command(self, command: MqttCommand) -> None:
        """An MQTT command: select/autotrack, or a manual move that pauses autotracking."""
        from ptzd.mqtt.messages import (
            GotoPreset,
            Move,
            MoveDirection,
            SelectTarget,
            SetAutotrack,
            Stop,
            ZoomMove,
        )

        manual: Command
        if isinstance(command, SelectTarget):
            # the epoch time of the frame (as in the track messages) on the daemon's clock
            drawn_at = None
            if command.ts is not None:
                drawn_at = self.clock.now() - (time.time() - command.ts)
            self.select(command.bbox, drawn_at)
            self._set_autotrack(True)
            return
        if isinstance(command, SetAutotrack):
            if command.enabled:
                self._manual = False
                self._set_autotrack(True)
                return
            manual = STOP
        elif isinstance(command, GotoPreset):
            manual = Preset(PresetAction.GOTO, command.number)
        elif isinstance(command, Move):
            speed = self.config.control.manual_speed
            pan = {MoveDirection.LEFT: -speed, MoveDirection.RIGHT: speed}.get(command.direction, 0)
            tilt = {MoveDirection.DOWN: -speed, MoveDirection.UP: speed}.get(command.direction, 0)
            manual = Motion(pan=pan, tilt=tilt)
        elif isinstance(command, ZoomMove):
            manual = Motion(zoom=Zoom.IN if command.direction == "in" else Zoom.OUT)
        else:
            assert isinstance(command, Stop)
            manual = STOP
        self.release()
        self._manual = True
        self._set_autotrack(False)
        if isinstance(manual, Motion):
            now = self.clock.now()
            self._last_motion = manual
            self._last_sent = now
            # (between control ticks: the motion it replaces ran until now)
            self.estimate.command(manual.pan, manual.tilt, int(manual.zoom), now)
        if not self.commands.closed:
            self._queue((manual,), None, "manual")

    def _set_autotrack(self, enabled: bool) -> None:
        if self.bridge is not None:
            self.bridge.set_autotrack(enabled)

    # --- serial --------------------------------------------------------------------------

    async def _write(self, command: Command, source: str) -> None:
        """Send one command; a motion actually written becomes the published ptz/state."""
        await send_command(self.link, command)
        self.stats.commands_sent += 1
        if self.bridge is not None and isinstance(command, Motion):
            self.bridge.set_ptz_state(command.pan, command.tilt, int(command.zoom), source)

    async def _serial(self) -> None:
        await self._write(STOP, "auto")  # whatever the dome was doing before we started
        try:
            while True:
                try:
                    batch = await self.commands.get()
                except MailboxClosedError:
                    return
                for command in batch.commands:
                    await self._write(command, batch.source)
                if batch.frame_wall_time is not None:
                    self.stats.latencies.append(time.perf_counter() - batch.frame_wall_time)
        finally:
            for task in self._aux_tasks:  # the pipeline is done: stop taking commands etc.
                task.cancel()
            with contextlib.suppress(Exception):
                await self._write(STOP, "auto")
                self._final_stop_sent = True


def daemon_detector(config: Config) -> Detector | None:
    """The person detector the daemon runs (None with `acquisition.enabled = false`)."""
    if not config.acquisition.enabled:
        return None
    from ptzd.vision.detect.factory import build_detector

    return build_detector(config.detector)


def _move_box(homography: npt.NDArray[np.float64], box: BoxTuple) -> BoxTuple:
    """`box` (x, y, w, h) of the previous frame where `homography` puts it in this one."""
    mapped, _ = apply_homography(homography, centre_box(box)[None, :], np.zeros((1, 2)))
    cx, cy, w, h = (float(v) for v in mapped[0])
    return (cx - w / 2, cy - h / 2, w, h)


def _reidentified(decision: Decision) -> bool:
    return any(t.reason == "reidentified" for t in decision.transitions)


def _track_item(
    result: TrackResult | None,
    frame: FrameItem,
    pose: Pose,
    velocity: tuple[float, float],
    acquired: BoxTuple | None,
    generation: int,
    decision: Decision | None,
    tracker: str | None,
) -> TrackItem:
    tracker = None if result is None else tracker  # no box, no tracker that made it
    if decision is None:
        return TrackItem(result, frame, pose, velocity, acquired, generation, tracker=tracker)
    return TrackItem(result, frame, pose, velocity, acquired, generation,
                     state=str(decision.state), transitions=decision.transitions,
                     tracker=tracker)  # fmt: skip


def _track_input(item: TrackItem | None) -> TrackInput | None:
    if item is None or item.result is None:
        return None
    r = item.result
    return TrackInput(
        Box(*r.box),
        item.velocity,
        r.state,
        r.confidence,
        item.frame.capture_time,
        pose_reported=item.frame.pose is not None,
    )


def latency_percentiles(samples: deque[float] | list[float]) -> dict[str, float | None]:
    """p50 and p99 of latency samples in milliseconds (None without samples)."""
    if not samples:
        return {"p50_ms": None, "p99_ms": None, "count": 0}
    ordered = sorted(samples)

    def pick(q: float) -> float:
        return ordered[min(len(ordered) - 1, math.ceil(q * len(ordered)) - 1)] * 1000.0

    return {"p50_ms": pick(0.5), "p99_ms": pick(0.99), "count": len(ordered)}
