"""SVM + Lucas-Kanade tracker (Sun 2015, seed 004).

A box is described by its RGB 3x3x3 histogram and its uniform rotation-invariant LBP(8,1)
histogram (37 values, ptzd/vision/features.py). An SVM with the histogram-intersection
kernel separates the target from its background; Platt scaling (seed eqs. 5-7) turns its
decision value into P(target | box), the particle weight (eq. 8) of a learned particle
filter whose estimate is the probability-weighted mean (eq. 9).

The loop (seed Fig. 5): Lucas-Kanade affine template tracking (inverse compositional,
eq. 10) while its variance-normalised SSD error stays under h1; above it the particle filter
takes over until the tracked patch's confidence exceeds h2, when LK restarts from a fresh
template. Patches tracked with error < h1 or confidence > h2 - and confidence > h2 - join
the positives; after 15 new ones the SVM is retrained (with fresh background negatives).

Beyond the seed, rules for occlusions, where LK and the PF wait where the target went out
of sight: after a few frames without a confident box the SVM scores a grid of boxes around
the held box, growing with the wait, and a box it is confident of on two frames running is
taken (`SvmConfig.scan_after`; ptzd/vision/scan.py); a confident box it is not sure of is
challenged by the same grid and gives way to a box there it scores well above it, found on
two frames running (`challenge_below`: the cloud drifted onto a passer-by); while an
occlusion is coasted, a box the SVM is sure of where the coast has walked to is taken too
(`coast_scan`); while the walker is hidden, nothing behind where he went out of sight is
taken (`scan_ahead`); while LOST, a box the colour vote's model recognises is taken and the
SVM retrained on it (`colour_reacquire`); a confident box the colour vote's model calls
someone else gives way to a box near it the model recognises (`colour_challenge`: a
passer-by the 27-bin histogram cannot tell apart); once the target is occluded, only a
box the SVM is confident of (P of h2 or more) or a scan's find ends it (`occlusion_hysteresis`:
the PF's cloud wanders while he is hidden); and a box in which nothing moved for
`SvmConfig.still_frames` frames counts as occluded, the scan then taking only boxes in
which something moved (ptzd/vision/stillness.py); that box becomes a negative of every
retraining after (`still_negatives`). On a grey scene (thermal, night) the colour
histogram's 27 bins hold grey levels (`grey_levels`).
"""

from __future__ import annotations

from collections import deque
from enum import StrEnum

import cv2
import numpy as np
from numpy.typing import NDArray
from sklearn.svm import SVC

from ptzd.vision.color import ColourVote, is_colour
from ptzd.vision.config import LkMotion, SvmConfig, TrackerConfig
from ptzd.vision.features import ColourTextureMaps, region_of, to_bgr, to_grey
from ptzd.vision.learning import LearningGate
from ptzd.vision.likelihood import FloatArray, Frame
from ptzd.vision.particle_filter import (
    VELOCITY_SMOOTHING,
    SureSteps,
    apply_homography,
    ego_motion_matrix,
    zoom_homography,
)
from ptzd.vision.rf import sample_negatives
from ptzd.vision.scan import FoundTwice, grid_around, not_behind
from ptzd.vision.stillness import MotionMap, StillCounter, camera_still
from ptzd.vision.tracking import Box, TrackResult, TrackState, centre_box

_MIN_SIZE = 4.0
# boxes kept as negatives from the still rule's finds (SvmConfig.still_negatives)
_STILL_NEGATIVES = 20
# LK template = the box grown by this factor (context around the target; ours).
_LK_MARGIN = 1.3


class Mode(StrEnum):
    LK = "lk"
    PF = "pf"


def intersection_kernel(a: FloatArray, b: FloatArray) -> FloatArray:
    """K(a_i, b_j) = sum_d min(a_id, b_jd): the histogram-intersection kernel, len(a) x len(b)."""
    k: FloatArray = np.minimum(a[:, None, :], b[None, :, :]).sum(axis=2)
    return k


def _platt_objective(f: FloatArray, t: FloatArray, a: float, b: float) -> float:
    z = f * a + b
    # -sum t log p + (1 - t) log(1 - p) with p = 1 / (1 + exp(z)), without overflow
    return float(
        np.sum(np.where(z >= 0, t * z + np.log1p(np.exp(-z)), (t - 1) * z + np.log1p(np.exp(z))))
    )


def platt_fit(decision: FloatArray, labels: NDArray[np.bool_]) -> tuple[float, float]:
    """(A, B) of P(y=1|f) = 1 / (1 + exp(A f + B)) (seed eqs. 5-7).

    Targets are Platt's regularised t+ = (N+ + 1) / (N+ + 2), t- = 1 / (N- + 2); the fit is
    Newton's method with backtracking line search (Lin, Lin and Weng 2007).
    """
    n_pos = float(labels.sum())
    n_neg = float(labels.size - n_pos)
    t = np.where(labels, (n_pos + 1) / (n_pos + 2), 1 / (n_neg + 2))
    a, b = 0.0, float(np.log((n_neg + 1) / (n_pos + 1)))
    value = _platt_objective(decision, t, a, b)
    for _ in range(100):
        z = decision * a + b
        p = np.where(z >= 0, np.exp(-z) / (1 + np.exp(-z)), 1 / (1 + np.exp(z)))
        d1 = t - p
        d2 = p * (1 - p)
        g1, g2 = float(np.sum(decision * d1)), float(np.sum(d1))
        if abs(g1) < 1e-5 and abs(g2) < 1e-5:
            break
        h11 = float(np.sum(decision * decision * d2)) + 1e-12
        h22 = float(np.sum(d2)) + 1e-12
        h21 = float(np.sum(decision * d2))
        det = h11 * h22 - h21 * h21
        da = -(h22 * g1 - h21 * g2) / det
        db = -(-h21 * g1 + h11 * g2) / det
        slope = g1 * da + g2 * db
        step = 1.0
        while step >= 1e-10:
            new_value = _platt_objective(decision, t, a + step * da, b + step * db)
            if new_value < value + 1e-4 * step * slope:
                a, b, value = a + step * da, b + step * db, new_value
                break
            step /= 2
        else:
            break
    return a, b


def platt_probability(decision: FloatArray, a: float, b: float) -> FloatArray:
    z = decision * a + b
    p: FloatArray = np.where(z >= 0, np.exp(-z) / (1 + np.exp(-z)), 1 / (1 + np.exp(z)))
    return p


class SvmModel:
    """Intersection-kernel SVM with Platt-scaled outputs."""

    def __init__(self, c: float) -> None:
        self._c = c
        self._support: FloatArray = np.zeros((0, 37))
        self._dual: FloatArray = np.zeros(0)
        self._intercept = 0.0
        self.platt = (0.0, 0.0)

    def fit(self, x: FloatArray, y: NDArray[np.bool_]) -> None:
        svc = SVC(C=self._c, kernel="precomputed")
        svc.fit(intersection_kernel(x, x), y.astype(int))
        self._support = x[svc.support_]
        self._dual = svc.dual_coef_[0].astype(np.float64)
        self._intercept = float(svc.intercept_[0])
        self.platt = platt_fit(self.decision(x), y)

    def decision(self, x: FloatArray) -> FloatArray:
        """Signed distance-like SVM output, > 0 on the target side."""
        out: FloatArray = intersection_kernel(x, self._support) @ self._dual + self._intercept
        return out

    def probability(self, x: FloatArray) -> FloatArray:
        return platt_probability(self.decision(x), *self.platt)


# Each warp's parameters in terms of the affine ones (a1, a2, a3, a4, tx, ty): "scale" is
# a1 = a4 = s with a shift, "translation" the shift alone.
_LK_BASES: dict[LkMotion, FloatArray] = {
    "affine": np.eye(6),
    "scale": np.array([[1, 0, 0], [0, 0, 0], [0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]]),
    "translation": np.eye(6)[:, 4:],
}


class LucasKanade:
    """Inverse-compositional Lucas-Kanade on a small grey template (seed eq. 10).

    `motion` picks the warp: "affine" (the seed's six parameters), "scale" (a scale factor
    and a shift: the template's aspect is kept) or "translation".
    """

    def __init__(self, size: int, iterations: int, motion: LkMotion = "affine") -> None:
        self._size = size
        self._iterations = iterations
        # the warp's parameters as a basis of the six affine ones (a1..a4, tx, ty)
        self._basis = _LK_BASES[motion]
        self._template: FloatArray = np.zeros((1, 1))
        self._sd: FloatArray = np.zeros((1, 6))
        self._hessian_inv: FloatArray = np.eye(6)
        self.warp: FloatArray = np.eye(3)  # template coordinates -> image pixels
        self._variance = 1.0

    def set_template(self, grey: NDArray[np.uint8], box: FloatArray) -> None:
        # the template takes a margin of context: a flat target's own silhouette edges are
        # what LK aligns, and they must lie inside the template
        cx, cy = box[:2]
        w, h = box[2:] * _LK_MARGIN
        scale = self._size / max(w, h)
        tw, th = max(4, round(w * scale)), max(4, round(h * scale))
        self.warp = np.array(
            [[w / tw, 0.0, cx - w / 2], [0.0, h / th, cy - h / 2], [0.0, 0.0, 1.0]]
        )
        self._template = self._sample(grey, (tw, th))
        gy, gx = (np.asarray(g, dtype=np.float64) for g in np.gradient(self._template))
        v, u = np.mgrid[0:th, 0:tw].astype(np.float64)
        gx, gy, u, v = gx.ravel(), gy.ravel(), u.ravel(), v.ravel()
        affine_sd = np.column_stack([gx * u, gy * u, gx * v, gy * v, gx, gy])
        self._sd = affine_sd @ self._basis
        k = self._basis.shape[1]
        hessian = self._sd.T @ self._sd + np.eye(k) * 1e-6
        self._hessian_inv = np.asarray(np.linalg.inv(hessian), dtype=np.float64)
        self._variance = max(float(self._template.var()), 1.0)

    def _sample(self, grey: NDArray[np.uint8], size: tuple[int, int]) -> FloatArray:
        patch = cv2.warpAffine(
            grey,
            self.warp[:2],
            size,
            flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
            borderMode=cv2.BORDER_REPLICATE,
        )
        # smoothing widens the basin of convergence on flat, sharp-edged targets
        return np.asarray(cv2.GaussianBlur(patch.astype(np.float64), (5, 5), 1.5), np.float64)

    def track(self, grey: NDArray[np.uint8]) -> float:
        """Align the template to `grey`; returns the error mean(residual^2) / var(template)."""
        th, tw = self._template.shape
        residual = np.zeros(1)
        for _ in range(self._iterations):
            residual = (self._sample(grey, (tw, th)) - self._template).ravel()
            dp = self._basis @ (self._hessian_inv @ (self._sd.T @ residual))
            delta = np.array([[1 + dp[0], dp[2], dp[4]], [dp[1], 1 + dp[3], dp[5]], [0, 0, 1.0]])
            self.warp = self.warp @ np.linalg.inv(delta)
            if float(np.abs(dp[4:]).max()) < 0.01 and float(np.abs(dp[:4]).max()) < 1e-4:
                break
        residual = (self._sample(grey, (tw, th)) - self._template).ravel()
        return float(np.mean(residual * residual)) / self._variance

    def box(self) -> FloatArray:
        """The axis-aligned (cx, cy, w, h) of the warped template."""
        th, tw = self._template.shape
        corners = np.array([[0, 0, 1], [tw, 0, 1], [0, th, 1], [tw, th, 1.0]]) @ self.warp.T
        lo, hi = corners[:, :2].min(axis=0), corners[:, :2].max(axis=0)
        size = (hi - lo) / _LK_MARGIN
        return np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, size[0], size[1]])


class SvmTracker:
    """A `Tracker`: LK template tracking, falling back to the SVM particle filter."""

    def __init__(self, config: TrackerConfig) -> None:
        self._config = config
        self._svm_config: SvmConfig = config.svm
        self.model = SvmModel(config.svm.svm_c)
        self.lk = LucasKanade(
            config.svm.template_size, config.svm.lk_iterations, config.svm.lk_motion
        )
        self._rng = np.random.default_rng(config.seed)
        self._motion = MotionMap(config.stillness.diff_threshold)
        self._colour = ColourVote(config.color, config.gmm, config.svm.colour_weight)
        self._still = StillCounter(config.svm.still_frames, config.stillness.min_moving_fraction)
        self._uses_motion = config.svm.still_frames > 0 or config.svm.learn_needs_motion
        self._gate = LearningGate(
            config.svm.learn_needs_motion,
            config.svm.learn_needs_colour,
            config.stillness.min_moving_fraction,
            config.occlusion.similarity_threshold,
        )
        self._box: FloatArray = np.zeros(4)
        self._reference: FloatArray = np.ones(2)  # init (w, h), rescaled on zoom
        self._velocity: FloatArray = np.zeros(2)
        self._sure = SureSteps()  # the coast's velocity (`SvmConfig.coast`)
        self._coasting = False  # this occlusion's report walks on
        self._particles: FloatArray = np.zeros((config.svm.num_particles, 4))
        self.positives: deque[FloatArray] = deque(maxlen=config.svm.positives)
        # boxes the still rule let go: negatives for every retraining from then on
        self.still_negatives: deque[FloatArray] = deque(maxlen=_STILL_NEGATIVES)
        self.new_positives = 0
        self.learned_positives = 0  # positives added since init
        self.retrains = 0
        self.mode = Mode.LK
        self.lk_error = 0.0
        self._state = TrackState.LOST
        self._confidence = 0.0
        self._occluded = 0
        self._unsure = 0  # frames in a row without a confident box
        self._weak = 0  # frames in a row with a box under `challenge_below`
        self._finds = FoundTwice()  # the scan's finds
        self._off_colour = 0  # confident frames in a row the colour vote calls someone else
        self._grey = False  # features from grey levels (SvmConfig.grey_levels)
        self._initialised = False

    @property
    def state(self) -> TrackState:
        return self._state

    def _features(self, frame: NDArray[np.uint8], boxes: FloatArray) -> FloatArray:
        region = region_of(boxes, frame.shape)
        maps = ColourTextureMaps(frame, region, self._svm_config.grid, self._grey)
        return maps.histograms(boxes, self._svm_config.parts)

    def init(self, frame: Frame, box: Box) -> None:
        self._box = centre_box(box, check=True)
        cfg = self._svm_config
        self._rng = np.random.default_rng(self._config.seed)
        self._reference = self._box[2:].copy()
        # a grey scene (thermal, a day/night camera at night) is described in grey levels
        self._grey = cfg.grey_levels and not is_colour(frame, self._box)
        bgr = to_bgr(frame)
        # seed Fig. 3: positives are the boxes closest to the init box
        self.positives = deque(self._positives_at(bgr, self._box, cfg.positives), cfg.positives)
        self.still_negatives.clear()
        self._retrain(bgr)
        self.retrains = 0
        self.learned_positives = 0
        self._colour.init(frame, self._box)
        self.lk.set_template(to_grey(frame), self._box)
        self.mode = Mode.LK
        self._velocity = np.zeros(2)
        self._sure.restart(self._box)
        self._state = TrackState.TRACKING
        self._confidence = 1.0
        self._occluded = 0
        self._unsure = 0
        self._weak = 0
        self._finds.clear()
        self._off_colour = 0
        self._motion.reset(frame)
        self._still.reset()
        self._initialised = True

    def _positives_at(self, bgr: NDArray[np.uint8], box: FloatArray, count: int) -> FloatArray:
        """Features of `box` and `count` - 1 boxes closest to it (seed Fig. 3's positives)."""
        near = self._jitter(box, count - 1, 0.05, 0.03)
        return self._features(bgr, np.vstack([box[None], near]))

    def _jitter(self, box: FloatArray, count: int, shift: float, scale: float) -> FloatArray:
        noise = self._rng.standard_normal((count, 3))
        out = np.tile(box, (count, 1))
        out[:, :2] += noise[:, :2] * shift * box[2:]
        out[:, 2:] *= np.exp(noise[:, 2:3] * scale)
        np.maximum(out[:, 2:], _MIN_SIZE, out=out[:, 2:])
        return out

    def _retrain(self, bgr: NDArray[np.uint8]) -> None:
        cfg = self._svm_config
        negatives = sample_negatives(self._box, cfg.negatives, 2.0, bgr.shape, self._rng)
        neg = self._features(bgr, negatives)
        pos = np.array(self.positives)
        x = np.vstack([pos, neg, *self.still_negatives])
        y = np.zeros(x.shape[0], bool)
        y[: pos.shape[0]] = True
        self.model.fit(x, y)
        self.new_positives = 0
        self.retrains += 1

    def update(self, frame: Frame, ego_motion: NDArray[np.float64] | None = None) -> TrackResult:
        if not self._initialised:
            raise RuntimeError("init() the tracker before update()")
        cfg = self._svm_config
        homography = None if ego_motion is None else ego_motion_matrix(ego_motion)
        if homography is not None:
            self._apply(homography)
        if self._uses_motion:
            self._motion.update(frame, homography)
        bgr, grey = to_bgr(frame), to_grey(frame)
        if self.mode is Mode.LK:
            self.lk_error = self.lk.track(grey)
            box = self.lk.box()
            if self.lk_error > cfg.lk_error or not self._sane(box, frame.shape):
                self._start_particles()
        if self.mode is Mode.LK:
            candidates = box[None]
            if cfg.lk_size_check:
                # LK's new size only if the SVM prefers it to the last box's size at LK's
                # centre: a template refreshed on a box a little too big grows the box
                candidates = np.vstack([box, np.concatenate([box[:2], self._box[2:]])])
            prob = self.model.probability(self._features(bgr, candidates))
            best = int(np.argmax(prob))  # a tie keeps LK's
            box, confidence = candidates[best], float(prob[best])
            if cfg.lk_min_confidence and confidence < cfg.lk_min_confidence:
                # LK's template slid off the walker (it still fits the background it now
                # holds); the SVM no longer agrees: the learned PF takes over this frame
                self._start_particles()
        if self.mode is Mode.PF:
            box, confidence = self._particle_step(bgr)
        still = bool(cfg.still_frames) and self._still.count_box(self._motion, box)
        if still:
            confidence = 0.0  # on something that does not move: not the target
            if cfg.still_negatives and self._still.run == cfg.still_frames:
                # what the box held still for so long is the background: teach it so
                self.still_negatives.extend(self._features(bgr, self._jitter(box, 5, 0.05, 0.0)))
                self._retrain(bgr)
        jumped = False
        challenged = bool(cfg.challenge_below) and confidence < cfg.challenge_below
        self._weak = self._weak + 1 if challenged else 0
        found: tuple[FloatArray, float] | None = None
        if confidence > cfg.confidence:
            self._unsure = 0
            if challenged and cfg.scan_after and self._weak >= cfg.scan_after:
                # a box the SVM only half believes (a passer-by the cloud drifted onto)
                # gives way to one near it that it believes far more
                found = self._scan(bgr, self._weak, confidence + cfg.challenge_margin)
            if found is None:
                found = self._colour_challenge(bgr, box)
        else:
            self._unsure += 1
            self._off_colour = 0
            if cfg.scan_after and self._unsure >= cfg.scan_after:
                found = self._scan(bgr, self._unsure, cfg.confidence, hidden_walker=True)
            ahead = self._scan_coast(bgr) if cfg.coast_scan else None
            if ahead is not None and (found is None or ahead[1] >= found[1]):
                found = ahead
            if found is None and cfg.colour_reacquire and self._state is TrackState.LOST:
                found = self._colour_find(bgr, cfg.scan_max_radius)
        taken = self._finds.offer(None if found is None else found[0])
        if taken and found is not None:
            box, confidence = found
            if confidence < cfg.confidence:
                # a colour find the SVM does not believe: teach it, as at init
                self.positives.extend(self._positives_at(bgr, box, cfg.retrain_after))
                self._box = box
                self._retrain(bgr)
                confidence = float(self.model.probability(self._features(bgr, box[None]))[0])
            jumped = True
            if confidence >= cfg.challenge_below:
                self._weak = 0  # (a find it half believes is no end to the doubt)
            self.mode = Mode.PF  # so step 7 below restarts LK from the found box
            self._still.reset()
        self._confidence = confidence
        if jumped:  # the scan's find starts a new history: the jump is no step
            self._sure.restart(box, keep_velocity=True)
        else:
            self._sure.update(box, confidence >= cfg.coast_confidence)
        if confidence > cfg.confidence and not jumped:
            # the velocity learns only from confident frames: a box the SVM doubts (on
            # a look-alike, or lagging the walker) must not steer the particles
            a = VELOCITY_SMOOTHING
            self._velocity = (1 - a) * self._velocity + a * (box[:2] - self._box[:2])
        tracked_from = cfg.occluded_below
        if cfg.occlusion_hysteresis and self._occluded and not jumped:
            tracked_from = cfg.confidence  # hidden: only a confident box (h2) ends it
        if confidence >= tracked_from:
            self._box = box
            self._occluded = 0
            self._state = TrackState.TRACKING
        else:
            if self._occluded == 0:
                # a target that stopped (the still rule) stands where he is, hidden or not
                self._coasting = cfg.coast and not still
            self._occluded += 1
            self._state = (
                TrackState.LOST if self._occluded >= cfg.max_occluded else TrackState.OCCLUDED
            )
        if confidence > cfg.confidence:
            # step 7: a confident patch joins the positives; LK resumes from it
            if self.mode is Mode.PF:
                self.mode = Mode.LK
                self.lk.set_template(grey, self._box)
            elif self.lk_error < cfg.lk_error:
                self.lk.set_template(grey, self._box)  # template update on confident frames
            moved = self._motion.moving_fraction(self._box[None]) if self._uses_motion else None
            share = None if moved is None else float(moved[0])
            if self._gate.allows(bgr, self._box, share, camera_still(homography), self._colour):
                self.positives.append(self._features(bgr, self._box[None])[0])
                self._colour.adapt(bgr, self._box)
                self.new_positives += 1
                self.learned_positives += 1
                if self.new_positives >= cfg.retrain_after:
                    self._retrain(bgr)
        return self._result()

    def _scan(
        self,
        bgr: NDArray[np.uint8],
        waited: int,
        floor: float,
        *,
        hidden_walker: bool = False,
    ) -> tuple[FloatArray, float] | None:
        """The best box of a grid around the held box, if the SVM scores it above `floor`.

        The grid reaches further the longer the box has been doubted (`waited` frames).
        For a `hidden_walker`, only boxes not behind him (`_not_behind`).
        """
        cfg = self._svm_config
        growth = cfg.scan_growth * (waited - cfg.scan_after)
        radius = min(cfg.scan_max_radius, cfg.scan_radius + growth)
        grid = grid_around(self._box, radius, cfg.scan_step, bgr.shape)
        if hidden_walker:
            grid = grid[self._not_behind(grid)]
        found = self._best_box(bgr, grid, moving_only=bool(cfg.still_frames))
        return found if found is not None and found[1] > floor else None

    def _colour_find(
        self, bgr: NDArray[np.uint8], radius: float, floor: float = 0.0
    ) -> tuple[FloatArray, float] | None:
        """The box of a scan grid `radius` box widths round the held box, in which
        something moved (and not behind a hidden walker), that the colour vote's model
        likes best, with its SVM P, if its colour similarity reaches
        `occlusion.reacquire_threshold` and `floor`."""
        if not self._colour.active:
            return None
        grid = grid_around(self._box, radius, self._svm_config.scan_step, bgr.shape)
        grid = grid[self._not_behind(grid) & self._moving(grid)]
        if grid.shape[0] == 0:
            return None
        best, similarity = self._colour.best(bgr, grid)
        if similarity < max(self._config.occlusion.reacquire_threshold, floor):
            return None
        box = grid[best]
        return box, float(self.model.probability(self._features(bgr, box[None]))[0])

    def _colour_challenge(
        self, bgr: NDArray[np.uint8], box: FloatArray
    ) -> tuple[FloatArray, float] | None:
        """A box the SVM is sure of that the colour vote's model has called someone else
        (under `occlusion.similarity_threshold`) for `scan_after` frames in a row gives way
        to the box near it the model recognises (`SvmConfig.colour_challenge`): at least
        `occlusion.reacquire_threshold` and `colour_challenge_margin` above the held box,
        and one the SVM believes too (P over `confidence`)."""
        cfg = self._svm_config
        if not (cfg.colour_challenge and self._colour.active):
            return None
        similarity = self._colour.similarity(bgr, box)
        below = similarity < self._config.occlusion.similarity_threshold
        self._off_colour = self._off_colour + 1 if below else 0
        if not cfg.scan_after or self._off_colour < cfg.scan_after:
            return None
        floor = similarity + cfg.colour_challenge_margin
        found = self._colour_find(bgr, cfg.colour_challenge_radius, floor)
        return found if found is not None and found[1] > cfg.confidence else None

    def _moving(self, boxes: FloatArray) -> NDArray[np.bool_]:
        """Which `boxes` something moved in, as far as the motion map knows (all of them
        before it knows anything)."""
        moved = self._motion.moving_fraction(boxes)
        if moved is None:
            return np.ones(boxes.shape[0], bool)
        moving: NDArray[np.bool_] = moved >= self._still.min_fraction
        return moving

    def _not_behind(self, boxes: FloatArray) -> NDArray[np.bool_]:
        """Which `boxes` lie no more than half a box behind the held box along the coast's
        heading, while the target is hidden (OCCLUDED, then LOST) after an occlusion that was
        coasted, and the coast moves (`SvmConfig.scan_ahead`); all of them otherwise."""
        if not (self._svm_config.scan_ahead and self._coasting and self._occluded > 0):
            return np.ones(boxes.shape[0], bool)
        return not_behind(boxes, self._box, self._sure.velocity, float(self._box[2]))

    def _scan_coast(self, bgr: NDArray[np.uint8]) -> tuple[FloatArray, float] | None:
        """While an occlusion is coasted, the best box within a quarter of a box of where
        the coast has walked to by this frame, if the SVM is sure of it."""
        cfg = self._svm_config
        if not (self._coasting and self._state is TrackState.OCCLUDED):
            return None
        ahead = self._box.copy()
        ahead[:2] += (self._occluded + 1) * self._sure.velocity
        grid = grid_around(ahead, 0.25, cfg.scan_step, bgr.shape)
        found = self._best_box(bgr, grid, moving_only=False)
        return found if found is not None and found[1] >= cfg.coast_confidence else None

    def _best_box(
        self, bgr: NDArray[np.uint8], grid: FloatArray, *, moving_only: bool
    ) -> tuple[FloatArray, float] | None:
        """The box of `grid` the SVM scores highest, and its P (`moving_only`: of the boxes
        in which something moved, as far as the motion map knows). None for an empty grid."""
        if grid.shape[0] == 0:
            return None
        prob = self.model.probability(self._features(bgr, grid))
        if moving_only:
            prob = np.where(self._moving(grid), prob, 0.0)
        best = int(np.argmax(prob))
        return grid[best], float(prob[best])

    def _start_particles(self) -> None:
        """Hand over from LK to the learned PF: a particle cloud around the last box."""
        cfg = self._svm_config
        self.mode = Mode.PF
        self._particles = self._jitter(self._box, cfg.num_particles, cfg.sigma_xy, 0.0)

    def _sane(self, box: FloatArray, shape: tuple[int, ...]) -> bool:
        """LK's box is plausible: finite, in the frame, size within 2x of the last box."""
        if not np.all(np.isfinite(box)):
            return False
        ratio = box[2:] / self._reference
        inside = 0 <= box[0] < shape[1] and 0 <= box[1] < shape[0]
        return bool(inside and np.all(ratio > 0.5) and np.all(ratio < 2.0))

    def _particle_step(self, bgr: NDArray[np.uint8]) -> tuple[FloatArray, float]:
        """One learned-PF step (seed eqs. 8-9): diffuse, weigh by P(target), resample."""
        cfg = self._svm_config
        p = self._particles
        n = p.shape[0]
        noise = self._rng.standard_normal((n, 3))
        # ours: the particles drift with the target (the seed's random walk falls behind a
        # walker whose step is larger than sigma_xy; vtest.avi AUC 0.48 -> 0.57)
        drift = self._velocity if cfg.velocity_drift else 0.0
        p[:, :2] += drift + noise[:, :2] * cfg.sigma_xy * self._box[2:]
        p[:, 2:] *= np.exp(noise[:, 2:3] * cfg.sigma_scale)
        p[:, 0] = np.clip(p[:, 0], 0, bgr.shape[1] - 1)
        p[:, 1] = np.clip(p[:, 1], 0, bgr.shape[0] - 1)
        # one scale per particle: the init box's aspect, within 0.5..2 of its size
        ref_w, ref_h = self._reference
        p[:, 2] = np.clip(p[:, 2], 0.5 * ref_w, 2.0 * ref_w)
        p[:, 3] = p[:, 2] * (ref_h / ref_w)
        prob = self.model.probability(self._features(bgr, p))
        # Platt probabilities vary little over the cloud, and their weighted mean drifts to
        # the cloud's middle; raised to a power the weights peak on the target (ours;
        # vtest.avi PF-only success AUC 0.31 -> 0.52 at 16)
        prob = self._colour.weigh(bgr, p, prob**cfg.weight_power)
        # a hidden walker walks on: the cloud does not settle on a look-alike behind him
        prob = np.where(self._not_behind(p), prob, 0.0)
        total = float(prob.sum())
        weights = prob / total if total > 0 else np.full(n, 1.0 / n)
        estimate: FloatArray = weights @ p
        if cfg.size_weight_power != cfg.weight_power:
            # flatter weights for the size: a box too large loses P steeply and is still
            # pulled in; the slight preference for inner boxes pulls with the power
            flat = weights ** (cfg.size_weight_power / cfg.weight_power)
            estimate[2:] = (flat / flat.sum()) @ p[:, 2:]
        confidence = float(self.model.probability(self._features(bgr, estimate[None]))[0])
        self._particles = p[self._rng.choice(n, size=n, p=weights)]
        if cfg.size_restart:
            # resampled sizes spread further every frame the SVM's P is flat over them,
            # and a wider spread lets the weights lean further to the smaller boxes
            self._particles[:, 2:] = estimate[2:]
        return estimate, confidence

    def resembles(self, frame: Frame, box: Box) -> bool:
        """The SVM scores it as a tracked (not occluded) target would score."""
        centre = centre_box(box)[None]
        confidence = float(self.model.probability(self._features(to_bgr(frame), centre))[0])
        return confidence >= self._svm_config.occluded_below

    def rescale(self, factor: float, center: tuple[float, float]) -> None:
        zoom = zoom_homography(factor, center)
        self._apply(zoom)
        self._motion.transform(zoom)
        self._colour.rescale(factor)

    def _apply(self, homography: FloatArray) -> None:
        zeros = np.zeros((self._particles.shape[0], 2))
        self._particles, _ = apply_homography(homography, self._particles, zeros)
        box, vel = apply_homography(homography, self._box[None], self._velocity[None])
        old_size = self._box[2:].copy()
        self._box, self._velocity = box[0], vel[0]
        self._sure.transform(homography)
        self._reference = self._reference * np.sqrt(np.prod(self._box[2:] / old_size))
        self.lk.warp = homography @ self.lk.warp
        self._finds.transform(homography)

    def _result(self) -> TrackResult:
        cx, cy, w, h = (float(v) for v in self._box)
        vx, vy = (float(v) for v in self._velocity)
        if self._state is TrackState.OCCLUDED and self._coasting:
            # the search stays where the target went out of sight; the report walks on
            vx, vy = (float(v) for v in self._sure.velocity)
            cx, cy = cx + self._occluded * vx, cy + self._occluded * vy
        elif self._state is not TrackState.TRACKING:
            vx, vy = 0.0, 0.0  # the box is held: so is what it reports moving
        return TrackResult(
            box=(cx - w / 2, cy - h / 2, w, h),
            state=self._state,
            confidence=float(np.clip(self._confidence, 0.0, 1.0)),
            velocity=(float(vx), float(vy)),
        )
