"""The weighted-resampling particle filter (Chang 2020, seed 002) with occlusion handling.

State per particle: (x, vx, y, vy, w, h), x and y the box centre (seed eq. 12). Per frame:
ego-motion compensation, prediction (seed eq. 14 constant velocity, or Ko 2013's
second-order autoregressive model), weighting by the pluggable likelihood, weighted-mean
estimate (eq. 15), occlusion test at the estimate, and - only while the target is visible -
Neff-triggered weighted resampling (eqs. 17-21) and the target-model update.
Every array operation runs over all particles at once; nothing loops over particles.
"""

from __future__ import annotations

from collections import deque

import numpy as np
from numpy.typing import NDArray

from ptzd.vision.config import ResamplingConfig, TrackerConfig
from ptzd.vision.likelihood import FloatArray, Frame, Likelihood
from ptzd.vision.stillness import MotionMap, StillCounter
from ptzd.vision.tracking import Box, TrackResult, TrackState, centre_box

# Column indices of the particle state.
X, VX, Y, VY, W, H = range(6)
# How much of each frame's centre displacement enters the reported velocity.
VELOCITY_SMOOTHING = 0.3  # share of a clean frame's step taken into the learned velocity
# At most this many boxes in a frame-wide re-acquisition scan.
_SCAN_MAX = 600


def effective_sample_size(weights: FloatArray) -> float:
    """N_eff = 1 / sum(w^2) of normalised weights (seed eq. 18)."""
    return float(1.0 / np.sum(weights * weights))


def weighted_resample(
    weights: FloatArray, config: ResamplingConfig, rng: np.random.Generator
) -> NDArray[np.intp]:
    """Indices of the resampled set: the seed's weighted resampling (eqs. 20-21).

    The top `top_rate` share of particles by weight each survive once; the remaining
    N - N_top slots are drawn from that top set in proportion to weight - by the seed's
    binary search on normalised cumulative weights (multinomial) or systematically.
    """
    n = weights.shape[0]
    n_top = min(n, max(1, round(config.top_rate * n)))
    top = np.argsort(-weights, kind="stable")[:n_top]
    top_weights = weights[top]
    total = float(top_weights.sum())
    cumulative = np.cumsum(top_weights) / total if total > 0 else np.arange(1, n_top + 1) / n_top
    draws = n - n_top
    if config.method == "systematic":
        r = (rng.random() + np.arange(draws)) / max(draws, 1)
    else:
        r = rng.random(draws)
    # smallest j with c'_j >= r (seed step 4c)
    picks = np.minimum(np.searchsorted(cumulative, r, side="left"), n_top - 1)
    return np.concatenate([top, top[picks]])


def map_points(homography: FloatArray, points: FloatArray) -> FloatArray:
    """Image points (n, 2) of the previous frame mapped into this one by `homography`."""
    mapped = np.column_stack([points, np.ones(len(points))]) @ homography.T
    out: FloatArray = mapped[:, :2] / mapped[:, 2:3]
    return out


def apply_homography(
    homography: FloatArray, boxes: FloatArray, velocities: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Map centre boxes (M x 4) and velocities (M x 2) from the previous frame to this one."""
    cx, cy, w, h = boxes.T
    probes = np.stack(
        [
            np.stack([cx, cy], 1),
            np.stack([cx - w / 2, cy], 1),
            np.stack([cx + w / 2, cy], 1),
            np.stack([cx, cy - h / 2], 1),
            np.stack([cx, cy + h / 2], 1),
            np.stack([cx, cy], 1) + velocities,
        ]
    )  # (6, M, 2)
    ones = np.ones((*probes.shape[:2], 1))
    mapped = np.concatenate([probes, ones], axis=2) @ homography.T
    mapped = mapped[..., :2] / mapped[..., 2:3]
    centre = mapped[0]
    new_w = np.linalg.norm(mapped[2] - mapped[1], axis=1)
    new_h = np.linalg.norm(mapped[4] - mapped[3], axis=1)
    out = np.column_stack([centre, new_w, new_h])
    return out, mapped[5] - centre


class SureSteps:
    """The velocity a target had while the tracker was sure of it: the median of the last
    `count` steps between sure centres, each per frame over the frames between them.

    What `svm`'s and `rf`'s boxes coast at once the target is hidden. An EMA of the steps of
    every fairly sure frame coasts too slowly: a walker sliding behind an occluder seems
    to slow down, and the box stalls on the frame his front reaches it while the tracker
    is still sure of it (docs/tracking.md, "The coast")."""

    def __init__(self, count: int = 7) -> None:
        self._steps: deque[FloatArray] = deque(maxlen=count)
        self._last: FloatArray = np.zeros(2)
        self._since = 0
        self.velocity: FloatArray = np.zeros(2)

    def restart(self, centre: FloatArray, *, keep_velocity: bool = False) -> None:
        """A new history from `centre` (init, or a jump that is no step)."""
        self._steps.clear()
        self._last, self._since = np.array(centre[:2], float), 0
        if not keep_velocity:
            self.velocity = np.zeros(2)

    def update(self, centre: FloatArray, sure: bool) -> None:
        """One frame: `centre` is taken if the tracker is `sure` of it."""
        self._since += 1
        if not sure:
            return
        self._steps.append((centre[:2] - self._last) / self._since)
        self.velocity = np.median(np.array(self._steps), axis=0)
        self._last, self._since = np.array(centre[:2], float), 0

    def transform(self, homography: FloatArray) -> None:
        """The camera moved (ego-motion, zoom): the history moves with the image."""
        vectors = np.vstack([self.velocity, *self._steps])  # all taken at the last centre
        at = np.tile(np.array([*self._last, 1.0, 1.0]), (len(vectors), 1))
        centres, moved = apply_homography(homography, at, vectors)
        self._last, self.velocity = centres[0, :2], moved[0]
        self._steps = deque(moved[1:], maxlen=self._steps.maxlen)


def ego_motion_matrix(ego_motion: NDArray[np.float64]) -> FloatArray:
    """A 3x3 homography from a shift (dx, dy) or a 3x3 matrix; ValueError otherwise."""
    m = np.asarray(ego_motion, dtype=np.float64)
    if m.shape == (2,):
        return np.array([[1.0, 0.0, m[0]], [0.0, 1.0, m[1]], [0.0, 0.0, 1.0]])
    if m.shape == (3, 3) and np.all(np.isfinite(m)) and abs(np.linalg.det(m)) > 1e-12:
        return m
    raise ValueError(f"ego_motion must be a shift (2,) or an invertible 3x3, got {m.shape}")


def zoom_homography(factor: float, center: tuple[float, float]) -> FloatArray:
    """The image scaled by `factor` about `center` (a zoom step); ValueError unless factor > 0."""
    if not factor > 0 or not np.isfinite(factor):
        raise ValueError(f"rescale factor must be positive, got {factor}")
    cx, cy = center
    return np.array(
        [[factor, 0.0, cx * (1 - factor)], [0.0, factor, cy * (1 - factor)], [0.0, 0.0, 1.0]]
    )


def ar2_drift(centres: deque[FloatArray]) -> FloatArray:
    """Ko 2013 eq. 13: the mean of the last two track velocities, floored to pixels."""
    c = list(centres)
    if len(c) >= 3:
        return np.floor(((c[-1] - c[-2]) + (c[-2] - c[-3])) / 2)
    if len(c) == 2:
        return c[-1] - c[-2]
    return np.zeros(2)


_RECENT_FRAMES = 50
# the stall test: frames in which the box must have stopped, after moving at its learned
# speed (at least _STALL_BEFORE of it) over as many frames before; stopped = under _STALL_NOW
_STALL_WINDOW = 4
_STALL_BEFORE = 0.6
_STALL_NOW = 0.25
# the fewest sure centres the coast's velocity is fitted to (else the reported velocity)
_FIT_MIN = 5


class ParticleTracker:
    """A `Tracker` over any `Likelihood`; deterministic for a given `config.seed`."""

    def __init__(self, config: TrackerConfig, likelihood: Likelihood) -> None:
        self._config = config
        self._likelihood = likelihood
        n = config.num_particles
        self._rng = np.random.default_rng(config.seed)
        self._particles: FloatArray = np.zeros((n, 6))
        self._weights: FloatArray = np.full(n, 1.0 / n)
        m = config.motion
        self._sigmas = np.array(
            [m.sigma_x, m.sigma_vx, m.sigma_y, m.sigma_vy, m.sigma_w, m.sigma_h]
        )
        self._box: FloatArray = np.zeros(4)  # reported box, centre form
        self._velocity: FloatArray = np.zeros(2)
        self._reference: FloatArray = np.ones(2)  # reference (w, h) for the scale bounds
        self._centres: deque[FloatArray] = deque(maxlen=3)  # for the AR2 model
        self._frame = 0  # updates so far
        # (frame, centre) of the last sure frames: what the coast's velocity is fitted to
        # (maxlen 0 with the fit off: nothing is kept, nothing mapped on ego-motion)
        self._sure_centres: deque[tuple[int, FloatArray]] = deque(
            maxlen=config.motion.coast_fit_frames
        )
        self._state = TrackState.LOST
        self._occluded_frames = 0
        self._lost_frames = 0
        self._reacquire_hits = 0  # consecutive LOST frames whose best candidate matched
        # observed centre steps of the last tracked frames (for the stall test)
        self._steps: deque[FloatArray] = deque(maxlen=2 * _STALL_WINDOW)
        # similarities of the last tracked frames: what this target usually scores
        self._recent: deque[float] = deque(maxlen=_RECENT_FRAMES)
        self._stalled = False  # occluded by a look-alike edge (see OcclusionConfig.stall_lag)
        # the box's centre when the target was last tracked: one end of the coast's path
        self._vanished_at: FloatArray | None = None
        self._confidence = 0.0
        still = config.stillness
        self._motion = MotionMap(still.diff_threshold) if still.still_frames else None
        self._still = StillCounter(still.still_frames, still.min_moving_fraction)
        self._candidate_moved = True  # something moved in the last candidate box (or unknown)
        self._initialised = False
        self.resampled = False  # whether the last update resampled (for tests and debugging)

    # -- public API -----------------------------------------------------------------------

    @property
    def particles(self) -> FloatArray:
        return self._particles

    @property
    def weights(self) -> FloatArray:
        return self._weights

    def init(self, frame: Frame, box: Box) -> None:
        centre = centre_box(box, check=True)
        w, h = float(centre[2]), float(centre[3])
        self._rng = np.random.default_rng(self._config.seed)
        target = np.array([centre[0], 0.0, centre[1], 0.0, w, h])
        n = self._config.num_particles
        # seed eq. 13: S_initial = I s_target + r.v.
        self._particles = target + self._rng.standard_normal((n, 6)) * self._sigmas
        self._weights = np.full(n, 1.0 / n)
        self._reference = np.array([w, h])
        self._box = centre
        self._velocity = np.zeros(2)
        self._centres.clear()
        self._centres.append(centre[:2].copy())
        self._sure_centres.clear()
        self._constrain(frame)
        self._likelihood.init(frame, centre)
        self._state = TrackState.TRACKING
        self._occluded_frames = 0
        self._stalled = False
        self._vanished_at = None
        self._steps.clear()
        self._recent.clear()
        self._lost_frames = 0
        self._reacquire_hits = 0
        self._confidence = 1.0
        self._still.reset()
        self._candidate_moved = True
        if self._motion is not None:
            self._motion.reset(frame)
        self._initialised = True

    def update(self, frame: Frame, ego_motion: NDArray[np.float64] | None = None) -> TrackResult:
        if not self._initialised:
            raise RuntimeError("init() the tracker before update()")
        self._frame += 1
        homography = None if ego_motion is None else ego_motion_matrix(ego_motion)
        if homography is not None:
            self._apply(homography)
        if self._motion is not None:
            self._motion.update(frame, homography)
        self._predict()
        if self._state is TrackState.LOST:
            self._search(frame)
        self._constrain(frame)
        boxes = self._particles[:, [X, Y, W, H]]
        log_l = self._likelihood.log_likelihood(frame, boxes)
        if self._state is TrackState.LOST:
            log_l = log_l - self._still_penalty(boxes)
        weights = np.exp(log_l - log_l.max())
        self._weights = weights / weights.sum()
        was_lost = self._state is TrackState.LOST
        if was_lost:
            # the spread cloud can hold several look-alikes: test the best particle itself,
            # not a mean between them
            candidate = self._particles[int(np.argmax(self._weights))][[X, Y, W, H]]
        else:
            estimate = self._estimate()
            # the occlusion test looks at the box we would report: estimate centre, smoothed size
            rate = self._config.scale.rate
            candidate = np.concatenate(
                [estimate[:2], (1 - rate) * self._box[2:] + rate * estimate[2:]]
            )
        parts = self._likelihood.part_similarities(frame, candidate)
        sim, weakest = float(parts.mean()), float(parts.min())
        self._confidence = sim
        if self._box_is_still(candidate, sim):
            sim = 0.0  # on something that does not move: not the person, however alike
        was_tracking = self._state is TrackState.TRACKING
        lag = self._stall_lag(candidate, sim) if was_tracking else None
        if lag is not None:
            self._stalled = True
            sim = 0.0  # occluded from this frame on
            # the coast starts where the target would be had it kept its speed (the coast
            # step below adds this frame's motion), and the cloud leaves the edge with it
            direction = self._velocity / np.hypot(*self._velocity)
            ahead = candidate[:2] + lag * direction - self._velocity
            self._particles[:, [X, Y]] += ahead - self._box[:2]
            self._particles[:, [VX, VY]] = self._velocity
            self._box[:2] = ahead
        elif self._stalled and sim < self._config.occlusion.reacquire_threshold:
            sim = 0.0  # still behind the look-alike: only a clean match ends it
        # half of him is in view (his top above a hedge): the box follows that half
        follows_part = self._shows_a_part(parts, candidate)
        self._transition(sim, weakest, follows_part, self._far_from_coast(candidate))
        if was_tracking and self._state is TrackState.OCCLUDED:
            self._vanished_at = self._box[:2].copy()
            if lag is None:
                self._velocity = self._coast_velocity()
        if self._state is not TrackState.OCCLUDED:
            self._stalled = False
        if self._state is TrackState.TRACKING:
            self._recent.append(self._confidence)
            self._steps.append(candidate[:2] - self._box[:2])
        else:
            self._steps.clear()
        self.resampled = False
        if self._state is TrackState.TRACKING:
            if was_lost:
                self._relock(candidate)
            self._follow(frame, candidate, learn_velocity=was_tracking)
        else:
            if self._reacquire_hits:
                # a candidate matched: gather the cloud on it to confirm next frame
                self._resample()
            if follows_part and self._state is TrackState.OCCLUDED:
                # learn nothing; the cloud gathers on the visible half
                self._resample()
                self._box[:2] = candidate[:2]
            else:
                self._coast()
        self._centres.append(self._box[:2].copy())
        return self._result()

    def rescale(self, factor: float, center: tuple[float, float]) -> None:
        zoom = zoom_homography(factor, center)
        self._apply(zoom)
        if self._motion is not None:
            self._motion.transform(zoom)
        # seed eqs. 34-38: the box keeps the reference aspect ratio across zoom steps
        aspect = self._reference[0] / self._reference[1]
        area = self._box[2] * self._box[3]
        self._box[2] = np.sqrt(area * aspect)
        self._box[3] = self._box[2] / aspect
        self._likelihood.rescale(factor)

    def resembles(self, frame: Frame, box: Box) -> bool:
        occ = self._config.occlusion
        parts = self._likelihood.part_similarities(frame, centre_box(box))
        if float(parts.min()) < occ.detection_part_threshold:
            return False  # half of it matches (same trousers, another shirt): someone else
        return float(parts.mean()) >= self._share_of_usual(occ.match_share)

    @property
    def state(self) -> TrackState:
        return self._state

    # -- steps ----------------------------------------------------------------------------

    def _apply(self, homography: FloatArray) -> None:
        """Move everything measured in the previous frame into this frame's pixels."""
        p = self._particles
        boxes, vel = apply_homography(homography, p[:, [X, Y, W, H]], p[:, [VX, VY]])
        p[:, [X, Y, W, H]] = boxes
        p[:, [VX, VY]] = vel
        old_size = self._box[2:].copy()
        box, v = apply_homography(homography, self._box[None, :], self._velocity[None, :])
        self._box, self._velocity = box[0], v[0]
        self._reference = self._reference * np.sqrt(np.prod(self._box[2:] / old_size))
        if self._centres:
            self._centres = deque(map_points(homography, np.array(self._centres)), maxlen=3)
        if self._vanished_at is not None:
            self._vanished_at = map_points(homography, self._vanished_at[None, :])[0]
        if self._sure_centres:
            frames = [f for f, _ in self._sure_centres]
            moved = map_points(homography, np.array([c for _, c in self._sure_centres]))
            self._sure_centres = deque(zip(frames, moved, strict=True), self._sure_centres.maxlen)

    def _predict(self) -> None:
        p = self._particles
        noise = self._rng.standard_normal(p.shape) * self._sigmas
        if self._state is not TrackState.TRACKING and not self._stalled:
            p[:, [VX, VY]] *= self._config.motion.occluded_velocity_decay
        if self._config.motion.model == "ar2":
            drift = ar2_drift(self._centres)
            if self._state is not TrackState.TRACKING:
                drift = self._velocity
            p[:, X] += drift[0] + noise[:, X]
            p[:, Y] += drift[1] + noise[:, Y]
            p[:, VX], p[:, VY] = drift[0], drift[1]
            # eq. 14: sizes scatter around the previous target size
            p[:, W] = self._box[2] + noise[:, W]
            p[:, H] = self._box[3] + noise[:, H]
        else:
            # seed 002 eq. 14: s_t = A s_{t-1} + r.v., A = constant velocity
            p[:, X] += p[:, VX]
            p[:, Y] += p[:, VY]
            p += noise

    def _search_radius(self) -> float:
        """Box sizes around the coasting box searched this frame: grows while occluded."""
        occ = self._config.occlusion
        frames = self._occluded_frames + self._lost_frames
        return min(occ.search_radius + occ.search_growth * frames, occ.max_search_radius)

    def _search(self, frame: Frame) -> None:
        """Re-acquisition proposals while LOST (the target model stays frozen).

        The lowest-weight `spread_share` of the particles are redrawn uniformly over the
        (growing) search region around the coasting box; every `scan_every` frames they are
        placed instead at the best boxes of a coarse scan of the whole frame. Not while a
        candidate is being confirmed: then the cloud stays gathered on it. (While only
        OCCLUDED the cloud just diffuses within the growing region: redrawing particles
        then would scatter the cloud on every one-frame similarity dip.)
        """
        occ = self._config.occlusion
        if self._reacquire_hits:
            return
        p = self._particles
        k = round(occ.spread_share * len(p))
        if k == 0:
            return
        idx = np.argsort(self._weights, kind="stable")[:k]
        size = self._box[2:]
        lost = self._state is TrackState.LOST
        if lost and occ.scan_every and self._lost_frames % occ.scan_every == 0:
            scan = self._scan_boxes(frame)
            scores = self._likelihood.log_likelihood(frame, scan) - self._still_penalty(scan)
            best = scan[np.argsort(-scores, kind="stable")[: max(1, k // 4)]]
            seeds = best[np.arange(k) % len(best)]
            jitter = self._rng.standard_normal((k, 2)) * (size / 8)
            centres = seeds[:, :2] + jitter
        else:
            reach = self._search_radius() * size
            centres = self._box[:2] + (2 * self._rng.random((k, 2)) - 1) * reach
        p[idx, X], p[idx, Y] = centres[:, 0], centres[:, 1]
        p[idx, VX] = 0.0
        p[idx, VY] = 0.0
        scale = 1.0 + 0.05 * self._rng.standard_normal(k)
        p[idx, W], p[idx, H] = size[0] * scale, size[1] * scale

    def _scan_boxes(self, frame: Frame) -> FloatArray:
        """Boxes of the current size on a grid over the frame: half a box apart, <= _SCAN_MAX."""
        height, width = frame.shape[:2]
        w, h = (float(v) for v in self._box[2:])
        step_x, step_y = w / 2, h / 2
        count = (width / step_x) * (height / step_y)
        if count > _SCAN_MAX:
            coarser = float(np.sqrt(count / _SCAN_MAX))
            step_x, step_y = step_x * coarser, step_y * coarser
        xs = np.arange(min(w / 2, width / 2), max(width - w / 2, width / 2) + 1e-6, step_x)
        ys = np.arange(min(h / 2, height / 2), max(height - h / 2, height / 2) + 1e-6, step_y)
        gx, gy = np.meshgrid(xs, ys)
        n = gx.size
        return np.column_stack([gx.ravel(), gy.ravel(), np.full(n, w), np.full(n, h)])

    def _constrain(self, frame: Frame) -> None:
        """Bounded scale and aspect; centres in the frame (and near the box when coasting)."""
        p = self._particles
        sc = self._config.scale
        ref_w, ref_h = self._reference
        height, width = frame.shape[:2]
        lo = np.array([0.0, -np.inf, 0.0, -np.inf, sc.min_scale * ref_w, sc.min_scale * ref_h])
        hi = np.array([width, np.inf, height, np.inf, sc.max_scale * ref_w, sc.max_scale * ref_h])
        if self._state is TrackState.OCCLUDED:
            # (while LOST the frame-wide scan may have put particles anywhere)
            reach = self._search_radius() * self._box[2:]
            lo[[X, Y]] = np.maximum(lo[[X, Y]], self._box[:2] - reach)
            hi[[X, Y]] = np.minimum(hi[[X, Y]], self._box[:2] + reach)
        np.clip(p, lo, hi, out=p)
        aspect = ref_h / ref_w
        tol = 1.0 + sc.aspect_tolerance
        np.clip(p[:, H], p[:, W] * aspect / tol, p[:, W] * aspect * tol, out=p[:, H])

    def _estimate(self) -> FloatArray:
        """Weighted mean state (seed eq. 15), optionally of the top share only."""
        p, w = self._particles, self._weights
        if self._config.estimate == "top":
            n_top = max(1, round(self._config.resampling.top_rate * len(w)))
            top = np.argsort(-w, kind="stable")[:n_top]
            p, w = p[top], w[top] / w[top].sum()
        state: FloatArray = w @ p
        return state[[X, Y, W, H]]

    def _far_from_coast(self, candidate: FloatArray) -> bool:
        """OCCLUDED, and `candidate` is further than `search_radius` box sizes (on either
        axis) from every point of the coast's path: from where the target was last tracked
        to the coasting box. (He may have stopped anywhere along it, or kept walking.)"""
        if self._state is not TrackState.OCCLUDED:
            return False
        end = self._box[:2]
        start = end if self._vanished_at is None else self._vanished_at
        path = end - start
        length2 = float(path @ path)
        along = 0.0 if length2 == 0 else float((candidate[:2] - start) @ path) / length2
        nearest = start + min(max(along, 0.0), 1.0) * path
        step = np.abs(candidate[:2] - nearest) / self._box[2:]
        return bool(step.max() > self._config.occlusion.search_radius)

    def _transition(
        self, similarity: float, weakest_part: float, follows_part: bool, far: bool
    ) -> None:
        """The state after a frame whose candidate scored `similarity` (the mean of its
        parts) and `weakest_part` (their minimum); `follows_part`: an occluded target's
        visible part is in view (the count towards LOST waits); `far`: the candidate is
        far from the coast's path (`_far_from_coast`)."""
        occ = self._config.occlusion
        if self._state is TrackState.LOST:
            self._lost_frames += 1
            # (no motion asked here: the search already prefers boxes in which something
            # moved, and a target found again may be standing still)
            whole = weakest_part >= occ.part_threshold
            if occ.reacquire and similarity >= occ.reacquire_threshold and whole:
                self._reacquire_hits += 1
                if self._reacquire_hits >= occ.reacquire_frames:
                    self._state = TrackState.TRACKING
                    self._occluded_frames = 0
                    self._lost_frames = 0
                    self._reacquire_hits = 0
            else:
                self._reacquire_hits = 0
            return
        # what comes back from an occlusion must match in every part, not on average
        whole = self._state is not TrackState.OCCLUDED or (
            weakest_part >= occ.part_threshold and self._moved_enough()
        )
        back = self._back_threshold()
        if far:
            back = max(back, occ.far_return_threshold)
        if similarity >= back and whole:
            self._state = TrackState.TRACKING
            self._occluded_frames = 0
            return
        # seed occlusion handler: no resampling, count, give up after max_frames
        if not follows_part:
            self._occluded_frames += 1
        self._state = (
            TrackState.LOST if self._occluded_frames >= occ.max_frames else TrackState.OCCLUDED
        )

    def _shows_a_part(self, parts: FloatArray, candidate: FloatArray) -> bool:
        """OCCLUDED, and the `candidate` box, whose parts scored `parts`, is a visible part
        of the target (see OcclusionConfig.follow_part_threshold and follow_max_step_*)."""
        occ = self._config.occlusion
        if not occ.follow_part_threshold or self._state is not TrackState.OCCLUDED:
            return False
        if self._stalled or len(parts) < 2:
            return False  # (a one-part model has no upper half)
        step = np.abs(candidate[:2] - self._box[:2]) / self._box[2:]
        if step[0] > occ.follow_max_step_x or step[1] > occ.follow_max_step_y:
            return False  # not level with the box: someone nearer or further back
        return bool(float(parts[0]) >= occ.follow_part_threshold and self._candidate_moved)

    def _moved_enough(self) -> bool:
        """Whether the candidate may end an occlusion as far as motion goes."""
        return self._candidate_moved or not self._config.occlusion.return_needs_motion

    def _box_is_still(self, box: FloatArray, similarity: float) -> bool:
        """Count the frames in which `box` did not move; whether there were `still_frames`,
        or `doubt_frames` with `similarity` under the learning threshold."""
        moved = None if self._motion is None else self._motion.moving_fraction(box)
        share = None if moved is None else float(moved[0])
        self._candidate_moved = share is None or share >= self._still.min_fraction
        if self._still.count(share):
            return True
        doubt = self._config.stillness.doubt_frames
        in_doubt = similarity < self._config.occlusion.learn_threshold
        return bool(doubt) and in_doubt and self._still.run >= doubt

    def _still_penalty(self, boxes: FloatArray) -> FloatArray | float:
        """While lost: what is taken off the log-likelihood of boxes in which nothing moved."""
        still = self._config.stillness
        moved = None if self._motion is None else self._motion.moving_fraction(boxes)
        if moved is None:
            return 0.0
        return np.where(moved < still.min_moving_fraction, still.lost_penalty, 0.0)

    def _back_threshold(self) -> float:
        """The similarity that keeps a tracked target tracked, or brings an occluded one back."""
        occ = self._config.occlusion
        if self._state is not TrackState.OCCLUDED:
            return occ.similarity_threshold
        return self._share_of_usual(occ.recover_share)

    def _share_of_usual(self, share: float) -> float:
        """`share` of what this target usually scores, and at least similarity_threshold."""
        occ = self._config.occlusion
        if not self._recent or share == 0:
            return occ.similarity_threshold
        usual = float(np.percentile(self._recent, 75))
        return max(occ.similarity_threshold, share * usual)

    def _stall_lag(self, candidate: FloatArray, similarity: float) -> float | None:
        """If a moving target's box is stuck on an occluder edge that resembles it: how far
        (px, along its motion) the box fell behind over the last `_STALL_WINDOW` frames.

        Stuck means: the similarity is in the grey zone and below `stall_drop` of what this
        target usually scores; over the `_STALL_WINDOW` frames before, the box moved at
        about its learned speed (so that speed is not stale: a walker slowing down over
        many grey frames is not stuck); over the last ones it nearly stopped, falling
        `stall_lag` box widths behind. Else None."""
        occ = self._config.occlusion
        speed = float(np.hypot(*self._velocity))
        if (
            occ.stall_lag <= 0
            or similarity >= occ.reacquire_threshold
            or similarity < occ.similarity_threshold
            or speed < occ.stall_min_speed * float(self._box[2])
            or len(self._steps) < 2 * _STALL_WINDOW - 1
            or len(self._recent) < _RECENT_FRAMES // 2
            # a target that always scores this low is not behind anything new
            or similarity > occ.stall_drop * float(np.percentile(self._recent, 75))
        ):
            return None
        direction = self._velocity / speed
        steps = [*self._steps, candidate[:2] - self._box[:2]][-2 * _STALL_WINDOW :]
        along = np.array([float(step @ direction) for step in steps])
        before, now = along[:_STALL_WINDOW], along[_STALL_WINDOW:]
        lag = _STALL_WINDOW * speed - float(now.sum())
        if (
            before.mean() < _STALL_BEFORE * speed
            or now.mean() > _STALL_NOW * speed
            or lag < occ.stall_lag * float(self._box[2])
        ):
            return None
        return lag

    def _resample(self) -> None:
        n = self._config.num_particles
        idx = weighted_resample(self._weights, self._config.resampling, self._rng)
        self._particles = self._particles[idx]
        self._weights = np.full(n, 1.0 / n)
        self.resampled = True

    def _relock(self, box: FloatArray) -> None:
        """Back from LOST at `box`: the coasting history says nothing about the target now.

        The size stays what it was before the loss: the search scattered the particles'
        sizes, and the best-matching one is biased small (a box on the most distinctive part
        of the target matches as well as the whole target), which the zoom would then
        "correct" by zooming in on that part."""
        box[2:] = self._box[2:]
        self._box = box.copy()
        self._velocity = np.zeros(2)
        self._particles[:, [VX, VY]] = 0.0
        self._centres.clear()
        self._sure_centres.clear()

    def _follow(self, frame: Frame, box: FloatArray, *, learn_velocity: bool) -> None:
        n = self._config.num_particles
        if effective_sample_size(self._weights) < self._config.resampling.neff_rate * n:
            self._resample()
        if learn_velocity and self._confidence >= self._config.occlusion.reacquire_threshold:
            # learn the velocity only from clean frames: a target sliding behind an occluder
            # appears to slow down, and coasting on that would leave it behind; and not from
            # the jump back out of a coast
            step = box[:2] - self._box[:2]
            a = VELOCITY_SMOOTHING
            self._velocity = (1 - a) * self._velocity + a * step
            self._sure_centres.append((self._frame, box[:2].copy()))
        self._box = box
        if self._confidence >= self._config.occlusion.learn_threshold:
            self._likelihood.adapt(frame, self._box)

    def _coast_velocity(self) -> FloatArray:
        """What a target hidden this frame coasts at: the least-squares velocity of its sure
        centres over the `coast_fit_frames` frames (MotionConfig) up to the last sure one,
        or, with fewer than _FIT_MIN of them, the reported velocity."""
        window = self._config.motion.coast_fit_frames
        if window == 0 or not self._sure_centres:
            return self._velocity
        last = self._sure_centres[-1][0]
        recent = [(f, c) for f, c in self._sure_centres if f > last - window]
        if len(recent) < _FIT_MIN:
            return self._velocity
        t = np.array([f for f, _ in recent], float)
        centres = np.array([c for _, c in recent])
        t -= t.mean()
        slope: FloatArray = t @ (centres - centres.mean(axis=0)) / float(t @ t)
        return slope

    def _coast(self) -> None:
        if not self._stalled:  # behind an occluder a walker walks on; otherwise slow down
            self._velocity = self._velocity * self._config.motion.occluded_velocity_decay
        self._box[:2] = self._box[:2] + self._velocity

    def _result(self) -> TrackResult:
        cx, cy, w, h = (float(v) for v in self._box)
        return TrackResult(
            box=(cx - w / 2, cy - h / 2, w, h),
            state=self._state,
            confidence=float(np.clip(self._confidence, 0.0, 1.0)),
            velocity=(float(self._velocity[0]), float(self._velocity[1])),
        )
