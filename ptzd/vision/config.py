"""Configuration of the tracker (`[tracker]` and its sub-tables).

Defaults follow the seed (Chang 2020, shared/seeds/002) where it gives a value; every
value the seed leaves open is marked as ours in config/ptzd.toml and docs/tracking.md.
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field, model_validator

from ptzd.schema import StrictModel


class MotionConfig(StrictModel):
    """Prediction step: how particles move between frames (state x, vx, y, vy, w, h)."""

    # constant_velocity: seed 002 eq. 14, s_t = A s_{t-1} + noise;
    # ar2: Ko 2013 eqs. 12-14, second-order autoregressive on the estimated track.
    model: Literal["constant_velocity", "ar2"] = "constant_velocity"
    # Seed 002's active-camera state covariance (10, 1, 10, 1, 1, 2), pixels per frame.
    sigma_x: float = Field(default=10.0, ge=0.0, le=200.0)
    sigma_vx: float = Field(default=1.0, ge=0.0, le=50.0)
    sigma_y: float = Field(default=10.0, ge=0.0, le=200.0)
    sigma_vy: float = Field(default=1.0, ge=0.0, le=50.0)
    sigma_w: float = Field(default=1.0, ge=0.0, le=50.0)
    sigma_h: float = Field(default=2.0, ge=0.0, le=50.0)
    # Velocity kept per frame while the target is occluded (1 = coast at full speed: a
    # hidden walker walks on; 0.95 left 28 % after 1 s at 25 fps and lost him).
    occluded_velocity_decay: float = Field(default=1.0, ge=0.0, le=1.0)
    # The velocity an occluded target coasts at (ours): fitted (least squares) to its sure
    # centres (similarity >= occlusion.reacquire_threshold) over this many frames up to the
    # last sure one; 0 = the running average of its steps that the tracked target reports,
    # which swings with a walker's bob. Off: measured mixed (docs/daemon.md, "second pass").
    coast_fit_frames: int = Field(default=0, ge=0, le=500)


class ColorConfig(StrictModel):
    """Colour likelihood: HSV kernel histograms compared with the Bhattacharyya coefficient."""

    bins_h: int = Field(default=6, ge=1, le=32)
    bins_s: int = Field(default=6, ge=1, le=32)
    bins_v: int = Field(default=6, ge=1, le=32)
    # Hue is noise for grey and near-black pixels: put them in hue bin 0 (beyond the seed).
    achromatic_collapse: bool = True
    # Soft value bins (beyond the seed): within `value_blend` bins of the edge between two
    # value bins, a pixel's weight is split between them, linearly with its distance from
    # the edge, instead of going whole to the bin it falls in. 0 = hard bins (the seed);
    # 1 = linear interpolation between the two nearest bin centres. rf's and svm's colour
    # vote keep hard bins (measured there with them). A shirt whose
    # brightness sits on an edge (V 165-175 against the edge at 171) otherwise flips
    # between two bins with the slightest shading, and its similarity to its own model
    # falls from 0.9 to 0.4 (synthetic:22; docs/tracking.md "Soft value bins"). 0.5 met
    # the closed-loop target in more runs than hard bins (96 against 95 of 120) and than
    # 0.4, 0.75 or 1; it costs about 0.7 ms a frame at 100 particles, 1.7 at 300.
    value_blend: float = Field(default=0.5, ge=0.0, le=1.0)
    # Fixed sampling grid per particle box (columns x rows).
    grid_cols: int = Field(default=16, ge=2, le=128)
    grid_rows: int = Field(default=32, ge=2, le=128)
    # Horizontal stripes with a histogram each, top to bottom (beyond the seed's one):
    # tells a dark jacket over jeans from a dark coat over dark trousers.
    parts: int = Field(default=2, ge=1, le=8)
    # Epanechnikov kernel radius: ellipse inscribed in the box, or the seed's a = sqrt(w^2+h^2).
    kernel: Literal["ellipse", "diagonal"] = "ellipse"
    # Beyond the seed: with `parts` >= 2 and the ellipse kernel, the top stripe's ellipse is at
    # most this many box heights wide (w/h), in the box's middle; 0 = inscribed in the box.
    # A box drawn round a walker mid-stride is as wide as his legs are apart, and at the
    # height of his head and shoulders its sides are ground, which then took the model: a
    # grey walker's box on grey paving went to a bench (docs/tracking.md).
    top_max_aspect: float = Field(default=0.45, ge=0.0, le=5.0)
    # Likelihood width: weight = exp(-(1 - rho) / (2 sigma^2)) (seed eq. 16).
    sigma: float = Field(default=0.1, gt=0.0, le=10.0)
    # Background-weighted target model (beyond the seed): down-weight colours of the ring
    # between the box and the box scaled by `ring_scale`.
    background_weighting: bool = True
    ring_scale: float = Field(default=2.0, gt=1.0, le=5.0)
    # Per-frame rate at which the ring histogram follows the current surroundings.
    background_rate: float = Field(default=0.1, ge=0.0, le=1.0)
    # The confidence measure (`part_similarities`: occlusion, re-acquisition, re-identification)
    # compares background-weighted histograms on both sides, the box's own as well as the
    # target model (beyond the seed): background-coloured pixels in the box then cost little
    # (a hedge coming into the top of a walker's box took his top part from 0.95 to 0.6 and
    # let a passer-by in the same trousers pass for him, synthetic:13). False: the plain
    # model against the plain box histogram (the particle weights use the weighted model
    # either way).
    weighted_confidence: bool = True
    # Scale cue (beyond the seed): a box's score is rho - scale_contrast * rho_ring, rho_ring
    # the similarity of the ring out to `contrast_scale` x the box to the target. A box too
    # small has a target-coloured ring, so the colour histogram no longer favours shrinking.
    scale_contrast: float = Field(default=0.5, ge=0.0, le=2.0)
    contrast_scale: float = Field(default=1.5, gt=1.0, le=3.0)

    @model_validator(mode="after")
    def _rows_split_into_parts(self) -> ColorConfig:
        if self.grid_rows % self.parts:
            raise ValueError("grid_rows must be a multiple of parts")
        return self


class GmmConfig(StrictModel):
    """Target-model update: K Gaussians per histogram bin (seed eqs. 22-27)."""

    components: int = Field(default=3, ge=1, le=8)
    # Mixing weights of the components in descending-pi order (seed eq. 23: A, B, C).
    mix: tuple[float, ...] = (0.6, 0.25, 0.15)
    alpha: float = Field(default=0.05, ge=0.0, le=1.0)
    beta: float = Field(default=0.01, ge=0.0, le=1.0)
    initial_sigma: float = Field(default=1.0, gt=0.0, le=10.0)
    # A bin is updated only if it moved less than this since the last frame (seed step 3).
    diff_threshold: float = Field(default=0.1, gt=0.0, le=1.0)

    @model_validator(mode="after")
    def _mix_matches_components(self) -> GmmConfig:
        if len(self.mix) != self.components:
            raise ValueError(f"mix needs {self.components} weights (one per component)")
        if any(m < 0 for m in self.mix) or abs(sum(self.mix) - 1.0) > 1e-6:
            raise ValueError("mix weights must be >= 0 and sum to 1")
        return self


class ResamplingConfig(StrictModel):
    """Neff-triggered weighted resampling (seed eqs. 17-21)."""

    # Resample when N_eff < neff_rate * N (seed eq. 19 `rate`).
    neff_rate: float = Field(default=0.5, gt=0.0, le=1.0)
    # Only the top `top_rate` share of particles reproduce (seed eq. 20, top = 0.2).
    top_rate: float = Field(default=0.2, gt=0.0, le=1.0)
    # multinomial: the seed's binary search on cumulative weights; systematic: lower variance.
    method: Literal["multinomial", "systematic"] = "multinomial"


class OcclusionConfig(StrictModel):
    """Colour occlusion handler: low similarity means occluded, not lost (seed Fig. 12)."""

    # ths_sim: below this the estimate is occluded (no resampling, no model update).
    similarity_threshold: float = Field(default=0.6, ge=0.0, le=1.0)
    # Give up (LOST) after this many consecutive occluded frames.
    max_frames: int = Field(default=30, ge=1, le=10_000)
    # The colour model learns (GMM update) only from tracked frames scoring at least this
    # (ours; 0 = from every tracked frame, the seed): a box stuck on an occluder in the
    # target's colours keeps scoring above similarity_threshold and would teach it the
    # occluder.
    learn_threshold: float = Field(default=0.75, ge=0.0, le=1.0)
    # What the target usually scores: the 75th percentile of its last 50 tracked frames.
    # A detection re-identifies a lost target only if it scores at least similarity_threshold
    # and at least `match_share` of that: someone else passing close by does not. 0 (the
    # default) asks similarity_threshold only: 0.8 also turned away the target itself, seen
    # over a pillar by a partial detection (synthetic:6, centred 0.90 -> 0.18).
    match_share: float = Field(default=0.0, ge=0.0, le=1.0)
    # Beyond the seed: an occluded or lost target is back only if every part of the colour
    # model (`color.parts`, top to bottom) scores at least this at the tracker's box, not
    # just their mean. Someone in the same trousers and another shirt scores 0.29-0.37 in
    # the top part and passes the mean; the target itself 0.75-0.8 (synthetic:0, walker 6
    # and the walker who comes out from behind the hedge). Not applied to a detection's
    # box (`resembles`): there the target's own top part scored 0.41-0.48. 0: off.
    part_threshold: float = Field(default=0.5, ge=0.0, le=1.0)
    # ... and a detection re-identifies the target (`resembles`) only if every part scores
    # at least this. With the plain measure half a look-alike scored 0.29-0.39 there (with
    # and without JPEG), the returning target 0.41-0.48 (synthetic:5), and the threshold was
    # 0.4; with `color.weighted_confidence` the returning target's top part scores 0.38-0.41
    # and a bigger passer-by's legs 0.26 (synthetic:7): a thin margin (docs/tracking.md).
    detection_part_threshold: float = Field(default=0.35, ge=0.0, le=1.0)
    # Hysteresis (beyond the seed): an occluded target is back only at `recover_share` of
    # what it usually scores. Off (0, the seed's single threshold) by default: 0.9 kept a
    # pillar's edge from passing for the target in synthetic:12, but held back walkers
    # coming out from behind someone in vtest.avi (vtest#3 failed for 2 of 3 tracker
    # seeds); the stillness test below catches the edge instead (docs/daemon.md).
    recover_share: float = Field(default=0.0, ge=0.0, le=1.0)
    # Beyond the seed: an occluded target coming back further than `search_radius` box
    # sizes (per axis) from the coast's path (from where he was last tracked to the coasting
    # box: he may have stopped anywhere along it) must score at least this. The search
    # region grows while he is hidden, and a look-alike across the view then passed for him
    # at the plain threshold (synthetic:21: walker 4 behind a column, the box back at 0.64
    # on part of a nearer walker 4 box widths away). 0: off (the plain threshold everywhere).
    # 0.8 (= reacquire_threshold): closed loop, 240 runs, mean centred 0.955 -> 0.960, in
    # view 0.975 -> 0.981 (docs/daemon.md, eleventh pass).
    far_return_threshold: float = Field(default=0.8, ge=0.0, le=1.0)
    # Beyond the seed: an occluded target is back only where something moved (the stillness
    # test's moving fraction, `stillness.min_moving_fraction`): a person coming out from
    # behind something is walking; a hedge or pavement in his colours is not. (A lost one
    # may be found standing; the search there already prefers boxes in which something moved.)
    return_needs_motion: bool = True
    # Beyond the seed: while OCCLUDED, a candidate whose top part (`color.parts` >= 2)
    # matches at least this, with something moving in it, is the target's upper half (above
    # a hedge, a bench, a car): the box follows it instead of coasting, nothing is learned,
    # and the count towards LOST waits. The top only: a passer-by in the same trousers
    # matched the bottom part and was followed off the target (docs/tracking.md). 0: off.
    follow_part_threshold: float = Field(default=0.75, ge=0.0, le=1.0)
    # ... and only a half level with the box and near it: the candidate's centre at most
    # `follow_max_step_x` box widths across and `follow_max_step_y` box heights up or down
    # from the box it would replace. A walker's own top stays on his row; a look-alike
    # further back or nearer stands higher or lower (synthetic:0's walker 23, gone behind a
    # column, was followed 100 px across and 43 px up onto another orange shirt).
    follow_max_step_x: float = Field(default=1.0, gt=0.0, le=20.0)
    follow_max_step_y: float = Field(default=0.2, gt=0.0, le=20.0)
    # Beyond the seed, an occluder edge: a target whose similarity sits between
    # similarity_threshold and reacquire_threshold, whose box moved at its learned speed and
    # then nearly stopped within 4 frames, falling `stall_lag` box widths behind, is taken
    # to be behind something that looks like it, not stopping. It is then occluded: it
    # coasts on at its speed (no decay), and only a match at reacquire_threshold ends it.
    # 0 (default) turns this off: it also fires on walkers who stop (docs/tracking.md);
    # 0.5 is the value measured.
    stall_lag: float = Field(default=0.0, ge=0.0, le=10.0)
    # Below this speed (box widths per frame) a target is standing: no stall test.
    stall_min_speed: float = Field(default=0.01, ge=0.0, le=1.0)
    # ... and only while its similarity is below this share of what it usually scores
    stall_drop: float = Field(default=0.88, gt=0.0, le=1.0)
    # While not tracking, particle centres stay within this many box sizes of the coasting box.
    search_radius: float = Field(default=1.5, gt=0.0, le=20.0)
    # While LOST keep searching and come back when similarity reaches this (beyond the seed).
    reacquire: bool = True
    reacquire_threshold: float = Field(default=0.8, ge=0.0, le=1.0)
    # Re-lock only after this many consecutive frames at reacquire_threshold (beyond the seed).
    reacquire_frames: int = Field(default=2, ge=1, le=100)
    # The search radius grows by this many box sizes per occluded frame, up to max_search_radius.
    search_growth: float = Field(default=0.1, ge=0.0, le=10.0)
    max_search_radius: float = Field(default=6.0, gt=0.0, le=50.0)
    # Share of the particles redrawn uniformly over the search region each frame while LOST
    # (the rest keep diffusing from where they were).
    spread_share: float = Field(default=0.3, ge=0.0, le=1.0)
    # While LOST, scan a coarse grid of boxes over the whole frame every this many frames and
    # seed particles at the best ones (0 = never).
    scan_every: int = Field(default=5, ge=0, le=1000)

    @model_validator(mode="after")
    def _reacquire_above_occlusion(self) -> OcclusionConfig:
        if self.reacquire_threshold < self.similarity_threshold:
            raise ValueError("reacquire_threshold must be >= similarity_threshold")
        if self.max_search_radius < self.search_radius:
            raise ValueError("max_search_radius must be >= search_radius")
        return self


class ScaleConfig(StrictModel):
    """Scale adaptation, bounded so the box neither collapses nor explodes (beyond the seed)."""

    # Share of the particles' mean size taken into the reported size per frame.
    rate: float = Field(default=0.1, ge=0.0, le=1.0)
    # Size limits relative to the reference size (the init box, rescaled on zoom). The
    # reference does not know the walker's distance: one walking away from the dome that
    # zooms in after him shrinks against it (synthetic:26: to 0.3 of it), so the floor is
    # low; 0.5 held that box at 1.4x his height (closed loop 97 -> 99/120 runs met).
    min_scale: float = Field(default=0.25, gt=0.0, le=1.0)
    max_scale: float = Field(default=2.0, ge=1.0, le=20.0)
    # Allowed relative deviation of a particle's aspect ratio from the reference one.
    aspect_tolerance: float = Field(default=0.15, ge=0.0, le=2.0)


class RfConfig(StrictModel):
    """Online random-forest tracker (Ko 2013, seed 000): thermal or visible grey input."""

    num_particles: int = Field(default=120, ge=10, le=5000)  # seed: N = 120
    # LID bins per subblock (seed: eight LID input variables).
    lid_bins: int = Field(default=8, ge=2, le=64)
    # LID samples per subblock side (ours: the kernel histogram is gathered on a grid).
    lid_samples: int = Field(default=6, ge=2, le=32)
    # OCS-LBP threshold T on centre-symmetric differences (seed: "a small value"; ours).
    ocs_threshold: float = Field(default=5.0, ge=0.0, le=255.0)
    trees: int = Field(default=4, ge=1, le=64)  # seed: 4 trees per forest
    max_depth: int = Field(default=20, ge=1, le=64)  # seed: depth 20
    # Features tried per node (seed: "m variables"; ours: ~sqrt(8)).
    features_per_node: int = Field(default=3, ge=1, le=64)
    # State from the top J particles (seed eq. 19: J = 15).
    top_particles: int = Field(default=15, ge=1, le=5000)
    sigma_xy: float = Field(default=6.4, ge=0.0, le=200.0)  # seed eq. 13
    sigma_wh: float = Field(default=0.64, ge=0.0, le=50.0)  # seed eq. 14
    # Beyond the seed: each particle's size is the box's times exp(N(0, sigma_scale)), one
    # factor for w and h (the aspect kept). The seed's +-0.64 px cannot follow a walker
    # who halves his height going away (vtest.avi). 0 = the seed's sigma_wh on w and h.
    sigma_scale: float = Field(default=0.03, ge=0.0, le=1.0)
    # Memory (seed sec. 4.3): 15 positives, 30 negatives, 5 early positives kept for good.
    positives: int = Field(default=15, ge=2, le=500)
    negatives: int = Field(default=30, ge=2, le=1000)
    kept_positives: int = Field(default=5, ge=0, le=500)
    # Learning condition (seed eqs. 21-22): U_max = min(u_cap, alpha / ln var), U_min = U_max - gap.
    u_cap: float = Field(default=0.72, ge=0.0, le=1.0)
    alpha: float = Field(default=5.4, gt=0.0, le=100.0)
    occlusion_gap: float = Field(default=0.4, ge=0.0, le=1.0)
    # T2: consecutive full-occlusion frames before the track is terminated (LOST).
    max_occluded: int = Field(default=30, ge=1, le=10_000)
    # Negatives: same-size boxes whose centre is this many box sizes away, at most (ours).
    negative_reach: float = Field(default=2.0, gt=0.6, le=10.0)
    # False: learn once on the first frame only (the static-RF ablation of seed sec. 5.4).
    online: bool = True
    # Beyond the seed: while occluded the box coasts on at the median step of the last
    # learning frames (kept coast_decay a frame; 2026-12-06: 1, it was 0.95 of an EMA) and
    # holds once the track is terminated; the particles search around it, their spread
    # growing by search_growth x sigma_xy per frame up to max_search_sigma x sigma_xy.
    # False: the seed's "previous particles and box" (the search stays where he was).
    coast: bool = True
    coast_decay: float = Field(default=1.0, ge=0.0, le=1.0)
    search_growth: float = Field(default=0.5, ge=0.0, le=10.0)
    max_search_sigma: float = Field(default=8.0, ge=1.0, le=100.0)
    # Beyond the seed (2026-12-04): motion evidence (`tracker.stillness`'s motion map, the
    # camera's motion taken out). Each particle's P is weighted by floor..1 after how much
    # moved in a box of the target's size on it, relative to the most-moving particle
    # (1 = off); and a box in which nothing moved for `still_frames` frames in a row is a
    # full occlusion whatever the forests say (0 = off): the forests learn the occluder a
    # walker went behind, and then score it above U_min for good (docs/tracking.md).
    motion_floor: float = Field(default=0.2, ge=0.0, le=1.0)
    still_frames: int = Field(default=15, ge=0, le=10_000)
    # Beyond the seed: a tracked box is not learned if nothing moved in it (the camera
    # still): the target is hidden or standing, and the box may show what he went behind;
    # nor, on colour frames, if the colour model (`tracker.color`) scores it under
    # `occlusion.similarity_threshold`. False = the seed's condition alone.
    learn_needs_motion: bool = True
    learn_needs_colour: bool = True
    # Beyond the seed: on colour frames each particle's P is multiplied by the colour
    # tracker's likelihood (`tracker.color`) to this power; its model learns on learning
    # frames. 0 = off (the seed's grey-level forests alone). Off on grey frames.
    colour_weight: float = Field(default=0.5, ge=0.0, le=10.0)
    # Beyond the seed, on colour frames: a learning or partial-occlusion estimate the colour
    # model scores under `occlusion.similarity_threshold` is a full occlusion, and the box
    # coasts (the grey-level forests score an occluder's edge, or a passer-by of the
    # walker's grey level, 0.5-0.7, and the box stayed on it); and a terminated (LOST) track
    # resumes on a partial-occlusion estimate the colour model scores at
    # `occlusion.reacquire_threshold` (otherwise only a learning frame, P over U_max,
    # resumes it). False = the seed's branches alone.
    colour_veto: bool = True
    colour_resume: bool = True

    @model_validator(mode="after")
    def _memory_fits(self) -> RfConfig:
        if self.kept_positives >= self.positives:
            raise ValueError("kept_positives must be < positives")
        if self.top_particles > self.num_particles:
            raise ValueError("top_particles must be <= num_particles")
        return self


LkMotion = Literal["affine", "scale", "translation"]  # SvmConfig.lk_motion


class SvmConfig(StrictModel):
    """SVM + Lucas-Kanade tracker (Sun 2015, seed 004)."""

    num_particles: int = Field(default=100, ge=10, le=5000)
    # Training set at init (seed: 50 positives near the box, 150 background negatives).
    positives: int = Field(default=50, ge=2, le=1000)
    negatives: int = Field(default=150, ge=2, le=2000)
    # Retrain after this many new positives (seed: 15).
    retrain_after: int = Field(default=15, ge=1, le=1000)
    svm_c: float = Field(default=1.0, gt=0.0, le=1000.0)
    # h1: LK residual (mean squared error / template variance) above which the PF takes
    # over. Ours: the seed's 0.003 belongs to a normalisation it does not spell out; at 0.1
    # LK's affine template slid off walkers in vtest.avi (docs/tracking.md).
    lk_error: float = Field(default=0.01, gt=0.0, le=10.0)
    # h2: Platt confidence above which LK resumes and the patch becomes a positive (seed 0.8).
    # Ours 0.5: with the box in `parts` bands a walker who turns or walks away scores
    # 0.5-0.8 on his own box, and at 0.8 the model stopped learning him (docs/tracking.md).
    confidence: float = Field(default=0.5, ge=0.0, le=1.0)
    # Beyond the seed: LK is trusted only while the SVM gives its box at least this
    # confidence; below, the learned PF takes over as on a large LK error. 0 = the seed.
    lk_min_confidence: float = Field(default=0.5, ge=0.0, le=1.0)
    # Beyond the seed: LK's new box size is kept only if the SVM scores it above the
    # last box's size at LK's centre (a template refreshed on a box a little too big
    # grows the box frame by frame). false = the seed.
    lk_size_check: bool = True
    # Beyond the seed (eq. 8 weighs by P itself): particle weights are P ** weight_power.
    weight_power: float = Field(default=16.0, ge=1.0, le=100.0)
    # Beyond the seed: the PF's size is the mean under weights P ** size_weight_power (its
    # position's are P ** weight_power), and with size_restart every frame's particles
    # start from that size. The SVM scores a box inside the walker a little above his whole
    # box, and under P ** 16 with sizes handed down by resampling the box shrank over a
    # long window (docs/tracking.md, "The PF's size from flatter weights"). The seed:
    # size_weight_power = weight_power and size_restart = false.
    size_weight_power: float = Field(default=8.0, ge=0.0, le=100.0)
    size_restart: bool = True
    # Below this confidence the target counts as occluded (ours).
    occluded_below: float = Field(default=0.3, ge=0.0, le=1.0)
    # Beyond the seed: once occluded, the target is back only on a box scored at h2
    # (`confidence`) or found by a scan, not on one just over `occluded_below`. While he is
    # hidden the PF's cloud wanders, and a box it settles on at P 0.3-0.5 took the track
    # away from where he came back (docs/tracking.md). false = `occluded_below` both ways.
    occlusion_hysteresis: bool = True
    max_occluded: int = Field(default=30, ge=1, le=10_000)
    # LK template at most this many pixels on its longer side; iterations per frame (ours).
    template_size: int = Field(default=32, ge=8, le=256)
    lk_iterations: int = Field(default=10, ge=1, le=100)
    # LK's warp: "affine" (the seed's eq. 10, six parameters), "scale" (one scale factor and
    # a shift, the init box's aspect kept, as the PF's particles) or "translation". Ours:
    # "scale"; the affine warp's free stretch let the box grow into the background above
    # walkers (vtest.avi AUC 0.580 -> 0.602, closed loop 19/27 -> 22/27; docs/tracking.md).
    lk_motion: LkMotion = "scale"
    # Feature sample grid per box side and PF random-walk sigma in box sizes (ours).
    grid: int = Field(default=16, ge=4, le=64)
    # Beyond the seed: the box's histograms per horizontal band, `parts` bands top to
    # bottom (37 values each): a whole-box histogram hardly minds where in the box the
    # walker is, so the box sat an eighth of the walker low (vtest.avi). 1 = the seed.
    parts: int = Field(default=2, ge=1, le=8)
    # Beyond the seed: on a grey scene (single-channel frames, or three equal channels in the
    # init box: thermal, a day/night camera at night) the colour histogram's 27 bins hold
    # grey levels; false = grey as RGB, three bins on the cube's diagonal.
    grey_levels: bool = True
    sigma_xy: float = Field(default=0.15, ge=0.0, le=5.0)
    sigma_scale: float = Field(default=0.02, ge=0.0, le=1.0)
    # Beyond the seed: the PF's particles drift by the target's velocity (learned from the
    # frames with confidence > h2) before the random walk; false = the seed's random walk.
    velocity_drift: bool = True
    # Beyond the seed: after `scan_after` frames in a row without a confident box (P <= h2),
    # the SVM also scores a grid of boxes (steps of `scan_step` box sizes) within `scan_radius`
    # box widths of the box, the radius growing by `scan_growth` widths a frame up to
    # `scan_max_radius`; a box there with P above h2 on two frames running is taken (the
    # walker who came out of an occlusion away from where the cloud waits). 0 = the seed.
    scan_after: int = Field(default=3, ge=0, le=10_000)
    scan_step: float = Field(default=0.25, gt=0.0, le=2.0)
    scan_radius: float = Field(default=1.0, ge=0.0, le=20.0)
    scan_growth: float = Field(default=0.1, ge=0.0, le=5.0)
    scan_max_radius: float = Field(default=8.0, ge=0.0, le=20.0)
    # Beyond the seed: a confident box under `challenge_below` (not sure) for `scan_after`
    # frames in a row is challenged by the same grid, its radius growing with the frames
    # since the last sure box, and a box there scoring `challenge_margin` above it on two
    # frames running is taken (the cloud drifted onto a passer-by the SVM half believes
    # while the target it believes is beside him). 0 = off.
    challenge_below: float = Field(default=0.9, ge=0.0, le=1.0)
    challenge_margin: float = Field(default=0.2, ge=0.0, le=1.0)
    # Beyond the seed: a box in which nothing moved for `still_frames` frames in a row is not
    # the target (LK and the SVM both hold on to a look-alike that does not move), so it
    # counts as occluded, and the scan takes only boxes in which something moved; the
    # thresholds are `[tracker.stillness]`'s. 0 = off.
    still_frames: int = Field(default=15, ge=0, le=10_000)
    # Beyond the seed: the box the still rule lets go (five jittered copies of it) joins the
    # negatives of every retraining from then on, and the SVM is retrained at once: LK and
    # the SVM had been holding on to the background a walker left. false = not learned.
    still_negatives: bool = True
    # Beyond the seed: on colour frames the PF's weights are multiplied by the colour
    # tracker's likelihood (`tracker.color`) to this power; its model learns from confident
    # boxes. 0 = off (the seed's SVM alone). Off on grey frames.
    colour_weight: float = Field(default=2.0, ge=0.0, le=10.0)
    # Beyond the seed: a confident box joins the positives only if something moved in it
    # (the camera still; ptzd/vision/learning.py). False = the seed's rule. The colour rule
    # rf has (the colour model scores the box at `occlusion.similarity_threshold`) is off:
    # in the closed loop it refused 28 confident boxes in a row on vtest#1 (tracker seed
    # 2), which then failed (centred 0.32 against 1.00 without it; docs/tracking.md).
    learn_needs_motion: bool = True
    learn_needs_colour: bool = False
    # Beyond the seed: while OCCLUDED the reported box walks on (a hidden walker walks on,
    # as `color` and `rf` have it, and the dome follows) at the velocity of the frames the
    # SVM is sure of (P >= coast_confidence: a walker sliding behind an occluder seems to
    # slow down); the PF and the scan stay where the target went out of sight. false = held.
    coast: bool = True
    coast_confidence: float = Field(default=0.9, ge=0.0, le=1.0)
    # Beyond the seed: while a coasted occlusion lasts, the boxes within a quarter of a box
    # of where the coast has walked to are scored too, and one scoring coast_confidence,
    # found on two frames running, is taken (he came out where the coast said, beyond the
    # scan's reach from where he went in). false = off.
    coast_scan: bool = True
    # Beyond the seed: while the target is hidden (OCCLUDED, then LOST) after a coasted
    # occlusion began, neither the scan nor the particles take a box more than half a box
    # behind where the target went out of sight, along the coast's heading (a hidden
    # walker walks on; a look-alike he passed stands behind him). Only when the coast
    # moves at least 0.02 box widths a frame. false = all round.
    scan_ahead: bool = True
    # Beyond the seed: while LOST, on colour frames, the box of the scan's widest grid (not
    # behind him, something moved in it) the colour vote's model likes best is found if it
    # scores occlusion.reacquire_threshold; found on two frames running it is taken and
    # the SVM retrained on it (a walker back in front of another background, whom the SVM
    # no longer knows). false = off.
    colour_reacquire: bool = True
    # Beyond the seed: on colour frames, a box the SVM is sure of that the colour vote's
    # model scores under occlusion.similarity_threshold for scan_after frames in a row
    # gives way to the box within colour_challenge_radius box widths, in which something
    # moved, that the model recognises (occlusion.reacquire_threshold and at least
    # colour_challenge_margin above the held box) and the SVM believes (P over
    # confidence), found on two frames running: the 27-bin RGB histogram cannot tell a
    # white shirt over black trousers from one over dark green, the colour model can
    # (a passer-by who crossed in front). false = off.
    colour_challenge: bool = True
    colour_challenge_radius: float = Field(default=2.0, ge=0.0, le=20.0)
    colour_challenge_margin: float = Field(default=0.2, ge=0.0, le=1.0)

    @model_validator(mode="after")
    def _occlusion_below_confidence(self) -> SvmConfig:
        if self.occluded_below > self.confidence:
            raise ValueError("occluded_below must be <= confidence")
        return self


class StillnessConfig(StrictModel):
    """Beyond the seeds: a box on something that does not move is not on the person.

    People move (walking, swaying, limbs); a colour look-alike in the background (a dark
    pole, a hedge, a pillar's edge) does not. Each frame the tracker marks the pixels that
    changed since the previous one, the camera's own motion removed (ptzd/vision/stillness.py).
    A box in which under `min_moving_fraction` of the pixels moved for `still_frames`
    frames in a row counts as occluded whatever its colour says (so it coasts, then is
    lost), and while lost, boxes in which nothing moves are searched last. A person who
    stands still that long is let go the same way; the dome then holds on them, and
    acquisition or the search takes them up again when they move.
    """

    # 0 turns the test off (the seeds' behaviour). 50 frames = 2 s at 25 fps. The colour
    # tracker's: rf has its own (`RfConfig.still_frames`), with this table's thresholds.
    still_frames: int = Field(default=50, ge=0, le=10_000)
    # A pixel moved when its grey level changed by more than this (sensor noise is ~2-5).
    diff_threshold: int = Field(default=20, ge=1, le=255)
    min_moving_fraction: float = Field(default=0.02, ge=0.0, le=1.0)
    # A box in doubt - similarity under `occlusion.learn_threshold`, so its model no longer
    # learns - is let go after this many still frames instead (0 = off): a box left on a
    # column's edge at 0.64-0.70 while the walker comes out on the other side (synthetic:28)
    # held the dome there for 2 s. A person who stands still matches better than that.
    doubt_frames: int = Field(default=20, ge=0, le=10_000)
    # While lost: log-likelihood taken off boxes in which nothing moved.
    lost_penalty: float = Field(default=3.0, ge=0.0, le=50.0)


TrackerKind = Literal["color", "rf", "svm"]


class AutoConfig(StrictModel):
    """`kind = "auto"`: one tracker for colour frames, another for monochrome ones (ours).

    A day/night camera drops its IR-cut filter at dusk and sends grey frames (still three
    channels from the decoder, all alike up to its rounding); a thermal camera sends grey
    always. Colour histograms carry nothing on grey frames, and a model learned in colour
    does not match the same person in near-infrared. Each frame's colour share is the share
    of its lit pixels, on a sparse grid, whose channels spread by 8 levels or more: 0 on a
    decoded grey frame (the decoder's rounding spreads them by 0-3), 0.2-0.85 on the views
    of vtest.avi the closed loop renders. Under `mono_below` a frame is monochrome, over
    `colour_above` colour, in between it is what the previous frame was; when it changes
    the other tracker takes over on the target's box (ptzd/vision/auto.py).
    """

    day: TrackerKind = "color"
    # rf: the best of the three on grey frames (docs/tracking.md "Day and night").
    night: TrackerKind = "rf"
    # Thresholds on the colour share (0..1). Decoded grey frames are at 0; the least
    # colourful view the closed loop rendered of the vtest tracks (a man in black on the
    # pale road) at 0.21.
    mono_below: float = Field(default=0.02, gt=0.0, le=1.0)
    colour_above: float = Field(default=0.05, gt=0.0, le=1.0)
    # Every this many pixels along each axis are looked at (a 640x480 frame: 4800 of them).
    sample_step: int = Field(default=8, ge=1, le=64)

    @model_validator(mode="after")
    def _band(self) -> AutoConfig:
        if self.colour_above < self.mono_below:
            raise ValueError("colour_above must be >= mono_below")
        return self


class FirstBoxConfig(StrictModel):
    """Beyond the seeds: a loose first box fitted to the moving person in it (ours;
    ptzd/vision/first_box.py, docs/tracking.md "A loose first box").

    The tracker starts on the box it is given. Over its first `frames` frames the pixels
    that moved are gathered (the camera's own motion taken out, `[tracker.stillness]`'s
    `diff_threshold`). Then the strips at each side of the box in which under
    `strip_fraction` of the pixels are on the person (moved, or between two moved pixels
    of their row or column) are trimmed, at most `max_trim` of the box from a side. The
    tracker starts again on the trimmed box when its area is under `refit_area_below` and
    its height under `refit_height_below` of the box's: a margin drawn round a person is a
    good share of the box and lies above his head or below his feet, while a tight box has
    little, and at its sides (a still arm, a planted leg). A box in which under
    `min_moving_fraction` moved (a person standing still), or with under
    `min_person_share` of the trimmed box on the person, is kept as it is. Boxes are
    answered in the framing they were drawn in.
    """

    enabled: bool = True
    # Frames of motion gathered (2 = 0.2 s at 10 fps). 1..50
    frames: int = Field(default=2, ge=1, le=50)
    strip_fraction: float = Field(default=0.05, ge=0.0, le=1.0)
    max_trim: float = Field(default=0.25, ge=0.0, lt=0.5)
    min_moving_fraction: float = Field(default=0.02, ge=0.0, le=1.0)
    # The trimmed box is trusted when at least this share of it is on the person (vtest's
    # walkers 0.63-0.94; a plain figure lagged by its box, moving only at one edge, 0.06).
    min_person_share: float = Field(default=0.3, ge=0.0, le=1.0)
    refit_area_below: float = Field(default=0.8, ge=0.0, le=1.0)
    refit_height_below: float = Field(default=0.9, ge=0.0, le=1.0)


class TrackerConfig(StrictModel):
    """Which tracker runs and its particle-filter parameters."""

    # auto: [tracker.auto]'s day tracker on colour frames, its night tracker on grey ones
    kind: Literal["color", "rf", "svm", "auto"] = "auto"
    num_particles: int = Field(default=300, ge=10, le=5000)
    seed: int = Field(default=0, ge=0)
    # mean: seed eq. 15 weighted mean of all particles; top: weighted mean of the top_rate share.
    estimate: Literal["mean", "top"] = "mean"
    motion: MotionConfig = MotionConfig()
    color: ColorConfig = ColorConfig()
    gmm: GmmConfig = GmmConfig()
    resampling: ResamplingConfig = ResamplingConfig()
    occlusion: OcclusionConfig = OcclusionConfig()
    scale: ScaleConfig = ScaleConfig()
    stillness: StillnessConfig = StillnessConfig()
    rf: RfConfig = RfConfig()
    svm: SvmConfig = SvmConfig()
    auto: AutoConfig = AutoConfig()
    first_box: FirstBoxConfig = FirstBoxConfig()
