"""Target acquisition and management: which person to follow, and when to give up.

Pure and clock-injected: `Acquirer.update(now, detections, track)` is called once per
processed frame with the detector's output (or None when no detection ran) and the
tracker's result, and returns a `Decision`: the state, the box to (re)initialise the
tracker on when a lock is made, and whether to send the camera home. State machine:

    searching --(candidate seen persist_frames frames, allowed by policy)--> tracking
    tracking  --(tracker reports occlusion or loses the target)--> occluded
    tracking  --(box static for static_s with no detection confirming it)--> searching
              (static in the world when the caller says how the camera moved the image)
    occluded  --(tracker recovers)--> tracking; --(detection near last box)--> tracking
    occluded  --(occluded_timeout_s)--> lost
    lost      --(recovered / re-identified / new candidate)--> tracking
    lost      --(lost_timeout_s)--> returning_home (go_home) or searching
    returning_home --(home_settle_s)--> searching

Every transition is logged and returned in `Decision.transitions` for the daemon to publish.
A track dropped as static is remembered for `ignore_static_s` so the same parked car or
mannequin is not locked again straight away.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from enum import StrEnum

from ptzd.logs import get_logger
from ptzd.vision.acquisition_config import AcquisitionConfig
from ptzd.vision.detect.types import Box, Detection, iou


class AcqState(StrEnum):
    SEARCHING = "searching"
    TRACKING = "tracking"
    OCCLUDED = "occluded"
    LOST = "lost"
    RETURNING_HOME = "returning_home"


@dataclass(frozen=True)
class TrackResult:
    """The tracker's view of the locked target this frame: `box` None once it gave up."""

    box: Box | None
    occluded: bool = False


@dataclass(frozen=True)
class Transition:
    """One state change, as logged and published."""

    t: float
    previous: AcqState
    state: AcqState
    reason: str
    box: Box | None

    def to_dict(self) -> dict[str, object]:
        return {
            "t": self.t,
            "from": self.previous.value,
            "state": self.state.value,
            "reason": self.reason,
            "bbox": None if self.box is None else [round(v, 1) for v in self.box],
        }


@dataclass(frozen=True)
class Decision:
    """What the pipeline should do after this frame."""

    state: AcqState
    target: Box | None
    lock_box: Box | None = None
    go_home: bool = False
    transitions: tuple[Transition, ...] = ()


@dataclass
class _Candidate:
    box: Box
    first_seen: float
    hits: int = 1
    misses: int = 0


@dataclass
class _Ignored:
    box: Box
    until: float


@dataclass
class _Target:
    box: Box
    locked_at: float
    anchor: Box
    anchor_t: float
    confirmed_t: float
    # chosen by an operator (MQTT select, `--init`): never switched away from by policy,
    # never dropped as static, and while it is lost nobody else is locked; only
    # `lost_timeout_s` ends it
    pinned: bool = False
    history: list[Transition] = field(default_factory=list)


def _centre(box: Box) -> tuple[float, float]:
    return (box[0] + box[2] / 2.0, box[1] + box[3] / 2.0)


def _moved(a: Box, b: Box) -> float:
    """Largest displacement of the centre or change of size between two boxes, pixels."""
    (ax, ay), (bx, by) = _centre(a), _centre(b)
    return max(math.hypot(ax - bx, ay - by), abs(a[2] - b[2]), abs(a[3] - b[3]))


class Acquirer:
    """The acquisition state machine for one camera view of `frame_size` (w, h) pixels."""

    def __init__(
        self,
        config: AcquisitionConfig,
        frame_size: tuple[int, int],
        *,
        on_transition: Callable[[Transition], None] | None = None,
    ) -> None:
        self._cfg = config
        self._size = frame_size
        self._on_transition = on_transition
        self._log = get_logger("acquire")
        self._state = AcqState.SEARCHING
        self._since = 0.0
        self._candidates: list[_Candidate] = []
        self._ignored: list[_Ignored] = []
        self._target: _Target | None = None
        self._last_box: Box | None = None
        self._last_detection_t = -math.inf
        # the dome followed a target since it was last sent home (so a long fruitless search
        # is probably happening somewhere odd: zoomed in, or where nobody walks)
        self._away_from_home = False

    @property
    def state(self) -> AcqState:
        return self._state

    @property
    def target(self) -> Box | None:
        return self._target.box if self._target is not None else None

    def wants_detection(self, now: float) -> bool:
        """Whether a detection should run for this frame (periodic while tracking)."""
        if self._state is AcqState.RETURNING_HOME:
            return False
        if self._state is AcqState.TRACKING:
            return now - self._last_detection_t >= self._cfg.revalidate_s
        return True

    # -- policy ---------------------------------------------------------------------------

    def _eligible(self, box: Box) -> bool:
        zone = self._cfg.zone
        if zone is None:
            return True
        cx, cy = _centre(box)
        w, h = self._size
        return zone[0] * w <= cx <= zone[2] * w and zone[1] * h <= cy <= zone[3] * h

    def _goodness(self, box: Box) -> float:
        """Larger is better: area, or closeness to the frame centre (inverse distance)."""
        if self._cfg.policy == "center":
            cx, cy = _centre(box)
            return 1.0 / (1.0 + math.hypot(cx - self._size[0] / 2.0, cy - self._size[1] / 2.0))
        return box[2] * box[3]

    def _ignored_box(self, box: Box, now: float) -> bool:
        self._ignored = [ig for ig in self._ignored if ig.until > now]
        return any(iou(box, ig.box) >= self._cfg.associate_iou for ig in self._ignored)

    def _confirmed_candidates(self, now: float) -> list[_Candidate]:
        return [
            c
            for c in self._candidates
            if c.hits >= self._cfg.persist_frames
            and c.misses == 0
            and self._eligible(c.box)
            and not self._ignored_box(c.box, now)
        ]

    # -- bookkeeping ----------------------------------------------------------------------

    def _associate(self, detections: Sequence[Detection], now: float) -> None:
        """Greedy IoU association of this frame's detections with the candidates."""
        boxes = [d.box for d in detections]
        pairs = sorted(
            (
                (iou(c.box, b), ci, bi)
                for ci, c in enumerate(self._candidates)
                for bi, b in enumerate(boxes)
            ),
            reverse=True,
        )
        used_c: set[int] = set()
        used_b: set[int] = set()
        for overlap, ci, bi in pairs:
            if overlap < self._cfg.associate_iou:
                break
            if ci in used_c or bi in used_b:
                continue
            used_c.add(ci)
            used_b.add(bi)
            cand = self._candidates[ci]
            cand.box = boxes[bi]
            cand.hits += 1
            cand.misses = 0
        kept = []
        for ci, cand in enumerate(self._candidates):
            if ci not in used_c:
                cand.misses += 1
                cand.hits = 0 if cand.misses > self._cfg.max_candidate_misses else cand.hits
            if cand.misses <= self._cfg.max_candidate_misses:
                kept.append(cand)
        kept.extend(_Candidate(b, now) for bi, b in enumerate(boxes) if bi not in used_b)
        self._candidates = kept

    def _go(self, now: float, state: AcqState, reason: str, out: list[Transition]) -> None:
        box = self.target if self._target is not None else self._last_box
        transition = Transition(now, self._state, state, reason, box)
        self._log.info(
            "acquisition_transition",
            previous=self._state.value,
            state=state.value,
            reason=reason,
            bbox=transition.to_dict()["bbox"],
        )
        self._state = state
        self._since = now
        out.append(transition)
        if self._on_transition is not None:
            self._on_transition(transition)

    def _lock(self, now: float, box: Box, reason: str, out: list[Transition]) -> Box:
        self._away_from_home = True
        self._target = _Target(box, now, box, now, now)
        self._last_box = box
        self._candidates = [
            c for c in self._candidates if iou(c.box, box) < self._cfg.associate_iou
        ]
        self._go(now, AcqState.TRACKING, reason, out)
        return box

    def _whole(self, box: Box) -> Box:
        """A re-found target's detection at the target's known height.

        Someone stepping out from behind a bench, a hedge or a pillar is often detected by
        the visible part only (head and shoulders); tracking that part would shrink the
        target and make the zoom close in on it. A detection shorter than `partial_height`
        of the last box keeps its top and horizontal centre and takes the last box's size.
        """
        last = self._last_box
        if last is None or box[3] >= self._cfg.partial_height * last[3]:
            return box
        x, y, w, _ = box
        return (x + w / 2 - last[2] / 2, y, last[2], last[3])

    def _near_last(
        self,
        detections: Sequence[Detection],
        reach: float,
        resembles: Callable[[Box], bool] | None,
    ) -> Box | None:
        """The detection nearest the last known target box, within `reach` box sizes and of
        a like size, taken whole (`_whole`), that the tracker says looks like the target
        (`resembles`; None: no appearance test). Someone else walking past is not the target
        however close: without the test the dome changed person at every crossing."""
        last = self._last_box
        if last is None:
            return None
        lx, ly = _centre(last)
        scale = max(last[2], last[3])
        best: tuple[float, Box] | None = None
        for det in detections:
            dx, dy = _centre(det.box)
            dist = math.hypot(dx - lx, dy - ly)
            ratio = (det.w * det.h) / max(1e-6, last[2] * last[3])
            nearer = best is None or dist < best[0]
            if dist > reach * scale or not 0.4 <= ratio <= 2.5 or not nearer:
                continue
            whole = self._whole(det.box)
            if resembles is None or resembles(whole):
                best = (dist, whole)
        return None if best is None else best[1]

    # -- the update -----------------------------------------------------------------------

    def select(self, now: float, box: Box) -> Decision:
        """An operator's target (or the initial box): lock it now, pinned (see `_Target`)."""
        out: list[Transition] = []
        self._lock(now, box, "selected", out)
        assert self._target is not None
        self._target.pinned = True
        return Decision(self._state, box, box, transitions=tuple(out))

    def reset(self, now: float) -> Decision:
        """Forget everything and start searching (e.g. autotrack switched back on)."""
        out: list[Transition] = []
        self._candidates = []
        self._target = None
        if self._state is not AcqState.SEARCHING:
            self._go(now, AcqState.SEARCHING, "reset", out)
        return Decision(self._state, None, transitions=tuple(out))

    def update(
        self,
        now: float,
        detections: Sequence[Detection] | None,
        track: TrackResult | None = None,
        *,
        camera_moving: bool = False,
        resembles: Callable[[Box], bool] | None = None,
        image_motion: Callable[[Box], Box] | None = None,
    ) -> Decision:
        """Advance the state machine by one frame; see the module docstring.

        `resembles` is the tracker's appearance test (`Tracker.resembles` on this frame): a
        detection re-identifies the lost target only if it passes.

        `image_motion` maps a box of the previous frame to where the camera's motion since
        then put it in this frame. Given, every box the acquirer remembers (the target's
        anchor, its last box, candidates, ignored boxes) moves with the view, and the static
        rule measures in the world: a box that stays put while the dome turns is static. Not
        given while `camera_moving`, the motion is unknown and restarts the static clock."""
        cfg = self._cfg
        out: list[Transition] = []
        lock_box: Box | None = None
        go_home = False
        if image_motion is not None:
            self._follow_view(image_motion)
        if detections is not None:
            self._last_detection_t = now
            self._associate(detections, now)
        state = self._state

        if state is AcqState.SEARCHING:
            lock_box = self._try_acquire(now, out)
            if (
                lock_box is None
                and cfg.return_home
                and cfg.search_timeout_s > 0
                and self._away_from_home
                and now - self._since >= cfg.search_timeout_s
            ):
                go_home = True
                self._go(now, AcqState.RETURNING_HOME, "search_timeout", out)

        elif state is AcqState.TRACKING:
            unknown_motion = camera_moving and image_motion is None
            lock_box = self._keep_tracking(now, detections, track, unknown_motion, out)

        elif state in (AcqState.OCCLUDED, AcqState.LOST):
            if track is not None and track.box is not None and not track.occluded:
                if self._target is not None:
                    self._target.box = track.box
                    self._target.anchor, self._target.anchor_t = track.box, now
                    self._target.confirmed_t = now
                self._last_box = track.box
                self._go(now, AcqState.TRACKING, "recovered", out)
            else:
                # while the tracker still searches on its own (a box, occluded) it is left to
                # it: a detection near the last box is often someone else passing
                gave_up = track is None or track.box is None
                pinned_target = self._target is not None and self._target.pinned
                reach = 1.0 if state is AcqState.OCCLUDED else 2.0
                found = None
                if detections and gave_up:
                    found = self._near_last(detections, reach, resembles)
                if found is not None:
                    pinned = self._target is not None and self._target.pinned
                    lock_box = self._lock(now, found, "reidentified", out)
                    assert self._target is not None
                    self._target.pinned = pinned  # still the operator's target
                elif (
                    state is AcqState.LOST
                    and gave_up
                    and not pinned_target  # an operator's target is waited for until timeout
                    and (acq := self._try_acquire(now, out)) is not None
                ):
                    lock_box = acq
                elif state is AcqState.OCCLUDED and now - self._since >= cfg.occluded_timeout_s:
                    self._go(now, AcqState.LOST, "occlusion_timeout", out)
                elif state is AcqState.LOST and now - self._since >= cfg.lost_timeout_s:
                    self._target = None
                    self._candidates = []
                    if cfg.return_home:
                        go_home = True
                        self._go(now, AcqState.RETURNING_HOME, "lost_timeout", out)
                    else:
                        self._go(now, AcqState.SEARCHING, "lost_timeout", out)

        elif state is AcqState.RETURNING_HOME and now - self._since >= cfg.home_settle_s:
            self._away_from_home = False
            self._candidates = []
            self._go(now, AcqState.SEARCHING, "home_reached", out)

        target = self._target.box if self._target is not None else None
        if self._state in (AcqState.SEARCHING, AcqState.RETURNING_HOME):
            target = None
        return Decision(self._state, target, lock_box, go_home, tuple(out))

    def _follow_view(self, move: Callable[[Box], Box]) -> None:
        """Carry every remembered box of the previous frame into this one (see `update`)."""
        target = self._target
        if target is not None:
            target.box, target.anchor = move(target.box), move(target.anchor)
        if self._last_box is not None:
            self._last_box = move(self._last_box)
        for candidate in self._candidates:
            candidate.box = move(candidate.box)
        for ignored in self._ignored:
            ignored.box = move(ignored.box)

    def _try_acquire(self, now: float, out: list[Transition]) -> Box | None:
        ready = self._confirmed_candidates(now)
        if not ready:
            return None
        best = max(ready, key=lambda c: self._goodness(c.box))
        return self._lock(now, best.box, "acquired", out)

    def _keep_tracking(
        self,
        now: float,
        detections: Sequence[Detection] | None,
        track: TrackResult | None,
        unknown_motion: bool,
        out: list[Transition],
    ) -> Box | None:
        cfg = self._cfg
        target = self._target
        assert target is not None  # TRACKING always has a target
        if track is None or track.box is None or track.occluded:
            self._go(
                now,
                AcqState.OCCLUDED,
                "occluded" if track and track.occluded else "track_lost",
                out,
            )
            return None
        target.box = track.box
        self._last_box = track.box
        still_px = max(cfg.static_px, cfg.static_fraction * track.box[3])
        if unknown_motion or _moved(track.box, target.anchor) > still_px:
            target.anchor, target.anchor_t = track.box, now
        if detections is not None and any(
            iou(d.box, track.box) >= cfg.confirm_iou for d in detections
        ):
            target.confirmed_t = now
        if target.pinned:
            return None
        if (
            not unknown_motion
            and now - target.anchor_t >= cfg.static_s
            and now - target.confirmed_t >= cfg.static_s
        ):
            self._ignored.append(_Ignored(track.box, now + cfg.ignore_static_s))
            self._target = None
            self._candidates = []
            self._go(now, AcqState.SEARCHING, "static", out)
            return None
        if detections is not None and now - target.locked_at >= cfg.min_switch_s:
            others = [
                c
                for c in self._confirmed_candidates(now)
                if iou(c.box, track.box) < cfg.confirm_iou
            ]
            if others:
                best = max(others, key=lambda c: self._goodness(c.box))
                if self._goodness(best.box) >= cfg.switch_margin * self._goodness(track.box):
                    return self._lock(now, best.box, "switched", out)
        return None
