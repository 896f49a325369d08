"""Online random-forest tracker (Ko 2013, seed 000), for thermal and grey input.

Per box: 3x2 subblocks, each with an LID and an OCS-LBP histogram (ptzd/vision/features.py);
per subblock two forests (LID, OCS-LBP) of `trees` trees: 12 forests. A particle's
likelihood is the mean positive probability of the 12 forests (eq. 17); the state is the
weighted mean of the top J particles (eqs. 18-19). The forests are relearned from a small
memory (sec. 4.3) only when the learning condition of sec. 4.5 holds:

- diff >= T1 (centre jump of at least half the box width): abnormal tracking - keep the
  previous forests, particles and box.
- P_t > U_max: learn (memory update, refit), resample all but the top J particles.
  While the memory is still filling (the first 15 tracked frames, sec. 4.3) every
  non-abnormal, non-occluded frame learns: a forest from 1 positive and 2 negatives
  rarely scores the target above 0.72, so the condition alone would never let it grow.
- U_min < P_t <= U_max: partial occlusion - no learning, resample all but the top J.
- P_t <= U_min: full occlusion - no learning, previous particles back, OC += 1;
  OC >= T2 terminates the track (LOST; the search goes on and a learning-grade frame
  resumes it, beyond the seed).

Beyond the seed, motion evidence (ptzd/vision/stillness.py): the particles' P is weighted
towards boxes in which something moved (`RfConfig.motion_floor`), and a box in which
nothing moved for `RfConfig.still_frames` frames is a full occlusion: forests that learned
the occluder a walker went behind otherwise keep scoring it above U_min for good. And so
that they learn it less, a box in which nothing moved this frame is not learned, nor, on
colour frames, one the colour model calls occluded (ptzd/vision/learning.py). On colour
frames the colour model also vetoes: an estimate it calls occluded is a full occlusion
whatever the forests say, and one it recognises resumes a terminated track
(`RfConfig.colour_veto`, `colour_resume`).

U_max = min(0.72, alpha / ln sigma^2), sigma^2 the intensity variance of the target box,
U_min = U_max - 0.4 (eqs. 21-22). Prediction is the second-order autoregressive model of
eqs. 12-14. Frames may be HxW, HxWx1 or HxWx3 (grey or BGR; white-hot or black-hot alike:
the forests learn whichever polarity the target has).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from enum import StrEnum

import numpy as np
from numpy.typing import NDArray

from ptzd.vision.color import ColourVote
from ptzd.vision.config import ResamplingConfig, RfConfig, TrackerConfig
from ptzd.vision.features import (
    ORIENTATIONS,
    SUBBLOCKS,
    FeatureMaps,
    region_of,
    to_grey,
)
from ptzd.vision.forest import ForestBank
from ptzd.vision.learning import LearningGate
from ptzd.vision.likelihood import FloatArray, Frame
from ptzd.vision.particle_filter import (
    VELOCITY_SMOOTHING,
    SureSteps,
    apply_homography,
    ar2_drift,
    ego_motion_matrix,
    map_points,
    weighted_resample,
    zoom_homography,
)
from ptzd.vision.stillness import MotionMap, StillCounter, camera_still, motion_weights
from ptzd.vision.tracking import Box, TrackResult, TrackState, centre_box

_MIN_SIZE = 4.0  # pixels: boxes never shrink below this


class Branch(StrEnum):
    """Which branch of the seed's online-learning procedure (sec. 4.5) a frame took."""

    LEARN = "learn"  # 2.3
    FULL_OCCLUSION = "full_occlusion"  # 2.4
    PARTIAL_OCCLUSION = "partial_occlusion"  # 2.5
    ABNORMAL = "abnormal"  # 3


def learning_bounds(variance: float, config: RfConfig) -> tuple[float, float]:
    """(U_min, U_max) of seed eqs. 21-22 for a target of intensity variance `variance`.

    For variance <= e the logarithm is <= 1 and alpha / ln var is not a probability bound;
    U_max is then the cap.
    """
    log_var = float(np.log(variance)) if variance > 0 else 0.0
    u_max = config.u_cap if log_var <= 1.0 else min(config.u_cap, config.alpha / log_var)
    return u_max - config.occlusion_gap, u_max


def choose_branch(diff: float, half_width: float, p: float, u_min: float, u_max: float) -> Branch:
    """The seed's learning condition (sec. 4.5, steps 1-3)."""
    if diff >= half_width:
        return Branch.ABNORMAL
    if p > u_max:
        return Branch.LEARN
    if p > u_min:
        return Branch.PARTIAL_OCCLUSION
    return Branch.FULL_OCCLUSION


@dataclass
class Example:
    features: FloatArray  # one feature row
    frame_index: int


class TrainingMemory:
    """Seed sec. 4.3: positives grow to `positives`, negatives to `negatives` at 1:2.

    The first `positives` positives fill the memory; then `kept` of them, spread evenly
    over those first frames, stay for good (against template drift) and the other slots
    form a queue of the newest. Negatives are replaced by each learning frame's background.
    """

    def __init__(self, positives: int, negatives: int, kept: int) -> None:
        self.capacity = positives
        self.negative_capacity = negatives
        self.kept_count = kept
        self.kept: list[Example] = []
        self.recent: deque[Example] = deque()
        self.negatives: FloatArray = np.zeros((0, 0))
        self._filled = False

    @property
    def positives(self) -> list[Example]:
        return self.kept + list(self.recent)

    def negatives_wanted(self) -> int:
        """Negatives to sample this frame: twice the positives, up to the capacity."""
        return min(2 * len(self.positives), self.negative_capacity)

    def add_positive(self, example: Example) -> None:
        if not self._filled:
            self.recent.append(example)
            if len(self.recent) == self.capacity:
                # freeze `kept` early positives spread over the first frames
                first = list(self.recent)
                keep = np.unique(np.linspace(0, len(first) - 1, self.kept_count).round()).astype(
                    int
                )
                self.kept = [first[i] for i in keep]
                rest = [e for i, e in enumerate(first) if i not in set(keep.tolist())]
                self.recent = deque(rest, maxlen=self.capacity - len(self.kept))
                self._filled = True
            return
        self.recent.append(example)  # the deque's maxlen drops the oldest

    def set_negatives(self, negatives: FloatArray) -> None:
        self.negatives = negatives

    def training_set(self) -> tuple[FloatArray, NDArray[np.bool_]]:
        pos = np.array([e.features for e in self.positives])
        x = np.vstack([pos, self.negatives]) if self.negatives.size else pos
        y = np.zeros(x.shape[0], bool)
        y[: pos.shape[0]] = True
        return x, y


class RfLikelihood:
    """Features and the 12 subblock forests; P(positive) of boxes (seed eq. 17)."""

    def __init__(self, config: RfConfig) -> None:
        self.config = config
        width = config.lid_bins + ORIENTATIONS
        # per subblock: LID columns, then OCS-LBP columns
        groups = []
        for i in range(SUBBLOCKS):
            start = i * width
            groups += [(start, start + config.lid_bins), (start + config.lid_bins, start + width)]
        self.forests = ForestBank(groups, config.trees, config.max_depth, config.features_per_node)
        self._maps: FeatureMaps | None = None
        self._maps_frame: Frame | None = None

    def maps(self, frame: Frame, cover: FloatArray) -> FeatureMaps:
        """Feature maps of `frame` covering `cover` boxes (kept for the rest of the frame)."""
        if self._maps is not None and self._maps_frame is frame:
            return self._maps
        grey = to_grey(frame)
        cfg = self.config
        self._maps = FeatureMaps(
            grey, region_of(cover, grey.shape), cfg.lid_bins, cfg.ocs_threshold
        )
        self._maps_frame = frame
        return self._maps

    def features(self, maps: FeatureMaps, boxes: FloatArray) -> FloatArray:
        """N x (6 * (lid_bins + 8)): per subblock its LID then its OCS-LBP histogram."""
        lid = maps.lid(boxes, self.config.lid_samples)
        ocs = maps.ocs_lbp(boxes)
        return np.concatenate([lid, ocs], axis=2).reshape(boxes.shape[0], -1)

    def probability(self, features: FloatArray) -> FloatArray:
        """Seed eq. 17: the mean over subblocks of (P_lid + P_ocs) / 2."""
        per_forest = self.forests.predict(features)
        out: FloatArray = per_forest.mean(axis=1)
        return out


def sample_negatives(
    box: FloatArray, count: int, reach: float, shape: tuple[int, ...], rng: np.random.Generator
) -> FloatArray:
    """`count` boxes the size of `box` around it, centres outside the box's middle.

    Offsets are uniform within `reach` box sizes; offsets with both |dx| < 0.6 w and
    |dy| < 0.6 h (mostly the target) are pushed out along their larger relative axis.
    Centres stay in the frame.
    """
    off = rng.uniform(-reach, reach, size=(count, 2))
    inside = np.all(np.abs(off) < 0.6, axis=1)
    axis = np.argmax(np.abs(off), axis=1)
    rows = np.nonzero(inside)[0]
    sign = np.where(off[rows, axis[rows]] >= 0, 1.0, -1.0)
    off[rows, axis[rows]] = sign * rng.uniform(0.6, reach, size=rows.size)
    centres = box[:2] + off * box[2:]
    centres[:, 0] = np.clip(centres[:, 0], 0, shape[1] - 1)
    centres[:, 1] = np.clip(centres[:, 1], 0, shape[0] - 1)
    return np.column_stack([centres, np.tile(box[2:], (count, 1))])


class RfTracker:
    """A `Tracker` implementing Ko 2013's online-RF particle filter."""

    def __init__(self, config: TrackerConfig) -> None:
        self._config = config
        self._rf_config = config.rf
        self.likelihood = RfLikelihood(config.rf)
        self._rng = np.random.default_rng(config.seed)
        rf = config.rf
        self.memory = TrainingMemory(rf.positives, rf.negatives, rf.kept_positives)
        self._particles: FloatArray = np.zeros((rf.num_particles, 4))
        self._box: FloatArray = np.zeros(4)
        self._centres: deque[FloatArray] = deque(maxlen=3)
        self._velocity: FloatArray = np.zeros(2)
        self._sure = SureSteps()  # the steps of the learning frames: what the coast walks at
        self._state = TrackState.LOST
        self._confidence = 0.0
        self.occluded_frames = 0  # OC of the seed
        self.branch: Branch | None = None  # branch taken by the last update
        self.learned_frames = 0
        self._frame_index = 0
        self._initialised = False
        still = config.stillness
        self._motion = MotionMap(still.diff_threshold)
        # with the motion rules off (the seed's tracker) the map is never fed: no per-frame cost
        self._uses_motion = rf.motion_floor < 1.0 or rf.still_frames > 0 or rf.learn_needs_motion
        self._camera_still = True  # no image motion handed in with the last frame
        self._still = StillCounter(rf.still_frames, still.min_moving_fraction)
        self._colour = ColourVote(config.color, config.gmm, rf.colour_weight)
        self._gate = LearningGate(
            rf.learn_needs_motion,
            rf.learn_needs_colour,
            still.min_moving_fraction,
            config.occlusion.similarity_threshold,
        )
        resample_share = rf.top_particles / rf.num_particles
        self._resampling = ResamplingConfig(top_rate=resample_share, method="systematic")

    @property
    def particles(self) -> FloatArray:
        return self._particles

    @property
    def state(self) -> TrackState:
        return self._state

    # -- Tracker API ----------------------------------------------------------------------

    def init(self, frame: Frame, box: Box) -> None:
        self._box = centre_box(box, check=True)
        rf = self._rf_config
        self._rng = np.random.default_rng(self._config.seed)
        self.memory = TrainingMemory(rf.positives, rf.negatives, rf.kept_positives)
        self._centres.clear()
        self._centres.append(self._box[:2].copy())
        self._velocity = np.zeros(2)
        self._sure.restart(self._box)
        self._particles = np.tile(self._box, (rf.num_particles, 1))
        self._frame_index = 0
        self.learned_frames = 0
        maps = self.likelihood.maps(frame, self._cover(self._box[None, :]))
        self._motion.reset(frame)
        self._still.reset()
        self._learn(frame, maps)
        self._colour.init(frame, self._box)
        self._state = TrackState.TRACKING
        self._confidence = 1.0
        self.occluded_frames = 0
        self.branch = None
        self._initialised = True

    def update(self, frame: Frame, ego_motion: NDArray[np.float64] | None = None) -> TrackResult:
        if not self._initialised:
            raise RuntimeError("init() the tracker before update()")
        self._frame_index += 1
        homography = None if ego_motion is None else ego_motion_matrix(ego_motion)
        if homography is not None:
            self._apply(homography)
        if self._uses_motion:
            self._motion.update(frame, homography)
        # while the camera turns, the image motion handed in is the commanded one, a little
        # off the real; the background's edges then "move" and would draw the particles
        self._camera_still = camera_still(homography)
        previous = self._particles.copy()
        self._predict(frame.shape)
        maps = self.likelihood.maps(frame, self._cover(self._particles))
        probs = self.likelihood.probability(self.likelihood.features(maps, self._particles))
        probs = self._colour.weigh(frame, self._particles, self._weigh_by_motion(probs))
        estimate, top = self._estimate(probs)
        diff = float(np.linalg.norm(estimate[:2] - self._box[:2]))
        p_t = float(self.likelihood.probability(self.likelihood.features(maps, estimate[None]))[0])
        u_min, u_max = learning_bounds(maps.variance(estimate), self._rf_config)
        # the abnormal-jump limit; while coasting, the target may turn up anywhere searched
        jump = self._box[2] / 2
        if self._coasting:
            jump = max(jump, 2.0 * self._search_sigma())
        branch = choose_branch(diff, jump, p_t, u_min, u_max)
        moved = self._motion.moving_fraction(estimate[None]) if self._uses_motion else None
        moved_share = None if moved is None else float(moved[0])
        if self._still.count(moved_share) and branch in (
            Branch.LEARN,
            Branch.PARTIAL_OCCLUSION,
        ):
            branch = Branch.FULL_OCCLUSION  # on something that does not move: not the target
        occlusion = self._config.occlusion
        colour = 1.0  # the colour model's similarity at the estimate, asked if it is followed
        if branch is Branch.LEARN or branch is Branch.PARTIAL_OCCLUSION:
            colour = self._colour.similarity(frame, estimate)  # 1.0 on grey frames
            if self._rf_config.colour_veto and colour < occlusion.similarity_threshold:
                branch = Branch.FULL_OCCLUSION  # what the forests took is not in his colours
        self.branch = branch
        self._confidence = p_t
        self._sure.update(estimate, sure=branch is Branch.LEARN)
        if branch is Branch.LEARN or branch is Branch.PARTIAL_OCCLUSION:
            self._move_to(estimate, learn_velocity=branch is Branch.LEARN)
            # sec. 4.3: the memory grows with every tracked frame until it is full
            growing = len(self.memory.positives) < self._rf_config.positives
            if (
                self._rf_config.online
                and (branch is Branch.LEARN or growing)
                and self._gate.allows(
                    frame, estimate, moved_share, self._camera_still, self._colour
                )
            ):
                self._learn(frame, maps)
                self._colour.adapt(frame, self._box)
            self._resample(probs, top)
            self.occluded_frames = 0
            # a learning-grade frame resumes a terminated track (beyond the seed), and so
            # does one the colour model recognises
            recognised = (
                self._rf_config.colour_resume
                and self._colour.active
                and colour >= occlusion.reacquire_threshold
            )
            if self._state is not TrackState.LOST or branch is Branch.LEARN or recognised:
                self._state = TrackState.TRACKING
        else:
            # 2.4 / 3: previous forests, particles and box
            # abnormal frames count too (beyond the seed): otherwise a target that really
            # moved fast would keep the tracker in the abnormal branch for good
            self.occluded_frames += 1
            if self._rf_config.coast:
                self._coast()
            else:
                self._particles = previous
                self._velocity = np.zeros(2)
                self._centres.append(self._box[:2].copy())
            if self.occluded_frames >= self._rf_config.max_occluded:
                self._state = TrackState.LOST
            elif self._state is TrackState.TRACKING:
                self._state = TrackState.OCCLUDED
        return self._result()

    def resembles(self, frame: Frame, box: Box) -> bool:
        """The forests call it positive (P > 0.5), as they call the target's own boxes."""
        return self.probability_at(frame, box) > 0.5

    def probability_at(self, frame: Frame, box: Box) -> float:
        """The forests' P (seed eq. 17) of `box` (top-left form) in `frame`."""
        centre = centre_box(box)[None]
        # fresh maps: the frame's cached ones cover the particles, not necessarily this box
        grey, cfg = to_grey(frame), self._rf_config
        region = region_of(self._cover(centre), grey.shape)
        maps = FeatureMaps(grey, region, cfg.lid_bins, cfg.ocs_threshold)
        return float(self.likelihood.probability(self.likelihood.features(maps, centre))[0])

    def rescale(self, factor: float, center: tuple[float, float]) -> None:
        zoom = zoom_homography(factor, center)
        self._apply(zoom)
        self._motion.transform(zoom)
        self._colour.rescale(factor)

    # -- steps ----------------------------------------------------------------------------

    def _cover(self, boxes: FloatArray) -> FloatArray:
        """Boxes the frame's feature maps must cover: `boxes` and the negatives' area."""
        reach = 2 * self._rf_config.negative_reach + 1
        grown = self._box * np.array([1.0, 1.0, reach, reach])
        return np.vstack([boxes, grown[None, :]])

    def _apply(self, homography: FloatArray) -> None:
        zeros = np.zeros((self._particles.shape[0], 2))
        self._particles, _ = apply_homography(homography, self._particles, zeros)
        box, vel = apply_homography(homography, self._box[None], self._velocity[None])
        self._box, self._velocity = box[0], vel[0]
        self._sure.transform(homography)
        if self._centres:
            self._centres = deque(map_points(homography, np.array(self._centres)), maxlen=3)

    def _predict(self, shape: tuple[int, ...]) -> None:
        """Seed eqs. 12-14: centres drift by the floored mean of the last two velocities;
        sizes by `sigma_scale` (ours) or the seed's `sigma_wh`.

        While coasting (occluded or lost, `RfConfig.coast`) the particles are drawn around
        the coasting box instead, with a spread that grows with the frames not tracked."""
        rf = self._rf_config
        n = self._particles.shape[0]
        noise = self._rng.standard_normal((n, 4))
        p = self._particles
        if self._coasting:
            p[:, :2] = self._box[:2] + noise[:, :2] * self._search_sigma()
        else:
            p[:, :2] += ar2_drift(self._centres) + noise[:, :2] * rf.sigma_xy
        if rf.sigma_scale:
            p[:, 2:] = self._box[2:] * np.exp(noise[:, 2:3] * rf.sigma_scale)
        else:
            p[:, 2:] = self._box[2:] + noise[:, 2:] * rf.sigma_wh
        p[:, 0] = np.clip(p[:, 0], 0, shape[1] - 1)
        p[:, 1] = np.clip(p[:, 1], 0, shape[0] - 1)
        np.maximum(p[:, 2:], _MIN_SIZE, out=p[:, 2:])

    def _estimate(self, probs: FloatArray) -> tuple[FloatArray, NDArray[np.intp]]:
        """Seed eqs. 18-19: normalised-weight mean of the top J particles."""
        j = self._rf_config.top_particles
        top = np.argsort(-probs, kind="stable")[:j]
        w = probs[top]
        total = float(w.sum())
        w = w / total if total > 0 else np.full(j, 1.0 / j)
        estimate: FloatArray = w @ self._particles[top]
        return estimate, top

    def _resample(self, probs: FloatArray, top: NDArray[np.intp]) -> None:
        """Keep the top J particles; draw the others from them in proportion to weight."""
        total = float(probs.sum())
        weights = probs / total if total > 0 else np.full(probs.shape, 1.0 / probs.size)
        idx = weighted_resample(weights, self._resampling, self._rng)
        self._particles = self._particles[idx]

    def _weigh_by_motion(self, probs: FloatArray) -> FloatArray:
        """The particles' P weighted by the motion in a box of the target's size on each
        (`RfConfig.motion_floor`): sizes are left to the forests, since a smaller box on
        the walker holds a larger share of moving pixels."""
        floor = self._rf_config.motion_floor
        if floor >= 1.0 or not self._camera_still:
            return probs
        centres = self._particles.copy()
        centres[:, 2:] = self._box[2:]
        weights = motion_weights(
            self._motion.moving_fraction(centres), floor, self._still.min_fraction
        )
        return probs if weights is None else probs * weights

    @property
    def _coasting(self) -> bool:
        """Occluded or lost, with `RfConfig.coast`: the box walks on, the search grows."""
        return self._rf_config.coast and self.occluded_frames > 0

    def _search_sigma(self) -> float:
        """Spread (px) of the particles around the box: sigma_xy, growing while coasting."""
        rf = self._rf_config
        if not self._coasting:
            return rf.sigma_xy
        return rf.sigma_xy * min(1.0 + rf.search_growth * self.occluded_frames, rf.max_search_sigma)

    def _coast(self) -> None:
        """Not tracked this frame: the box walks on at the median step of the last learning
        frames (`SureSteps`), kept `coast_decay` a frame, and holds once the track is
        terminated (LOST). The velocity history follows the box, so the drift resumes from
        there once the target is found."""
        rf = self._rf_config
        if self.occluded_frames == 1:
            self._velocity = self._sure.velocity.copy()
        if self.occluded_frames > rf.max_occluded:
            self._velocity = np.zeros(2)
        self._velocity = self._velocity * rf.coast_decay
        self._box[:2] = self._box[:2] + self._velocity
        self._centres.append(self._box[:2].copy())

    def _move_to(self, estimate: FloatArray, *, learn_velocity: bool) -> None:
        if learn_velocity:  # from learning-grade frames only: an occluded target lags
            step = estimate[:2] - self._box[:2]
            a = VELOCITY_SMOOTHING
            self._velocity = (1 - a) * self._velocity + a * step
        self._box = estimate.copy()
        self._centres.append(self._box[:2].copy())

    def _learn(self, frame: Frame, maps: FeatureMaps) -> None:
        """Seed 2.3.1-2.3.2: add the target, refresh the negatives, refit the forests."""
        lh = self.likelihood
        memory = self.memory
        memory.add_positive(Example(lh.features(maps, self._box[None])[0], self._frame_index))
        boxes = sample_negatives(
            self._box,
            memory.negatives_wanted(),
            self._rf_config.negative_reach,
            frame.shape,
            self._rng,
        )
        memory.set_negatives(lh.features(maps, boxes))
        x, y = memory.training_set()
        lh.forests.fit(x, y, self._rng)
        self.learned_frames += 1

    def _result(self) -> TrackResult:
        cx, cy, w, h = (float(v) for v in self._box)
        return TrackResult(
            box=(cx - w / 2, cy - h / 2, w, h),
            state=self._state,
            confidence=float(np.clip(self._confidence, 0.0, 1.0)),
            velocity=(float(self._velocity[0]), float(self._velocity[1])),
        )
