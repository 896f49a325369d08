"""Colour likelihood and GMM target model: vectorised histograms, peaks, hand-computed GMM."""

from __future__ import annotations

import gc
import weakref

import cv2
import numpy as np
import pytest

from ptzd.vision.color import (
    _PER_GRID,
    _SOFT_CHUNK,
    ColorLikelihood,
    background_weights,
    bhattacharyya,
    bin_image,
    box_histograms,
    kernel_grid,
    make_luts,
    pad_bins,
)
from ptzd.vision.config import ColorConfig, GmmConfig
from ptzd.vision.gmm import GmmTargetModel
from tests.vision_helpers import Scene


def _slow_histograms(frame, boxes, config: ColorConfig, parts: int):
    """Reference: loop over boxes and grid points, quantise each pixel on its own."""
    luts = make_luts(config)
    grid = kernel_grid(config.grid_cols, config.grid_rows, config.kernel, parts=parts)
    m = luts.n_bins
    height, width = frame.shape[:2]
    out = np.zeros((len(boxes), parts, m + 1))
    for n, (cx, cy, w, h) in enumerate(boxes):
        for r, v in enumerate(grid.v):
            for c, u in enumerate(grid.u):
                x = int(np.floor(cx + w * u))
                y = int(np.floor(cy + h * v))
                if not (0 <= x < width and 0 <= y < height):
                    out[n, grid.part[r], m] += grid.weights[r, c]
                    continue
                pixel = frame[y : y + 1, x : x + 1]
                hsv = cv2.cvtColor(pixel, cv2.COLOR_BGR2HSV_FULL)[0, 0].astype(int)
                for vb, share in _value_bins(int(hsv[2]), config):
                    hb = hsv[0] * config.bins_h // 256
                    sb = hsv[1] * config.bins_s // 256
                    if config.achromatic_collapse:
                        if sb == 0 or vb == 0:
                            hb = 0
                        if vb == 0:
                            sb = 0
                    b = (hb * config.bins_s + sb) * config.bins_v + vb
                    out[n, grid.part[r], b] += grid.weights[r, c] * share
    return out


def _value_bins(level: int, config: ColorConfig) -> list[tuple[int, float]]:
    """Value bins of an 8-bit level with their shares: one, or with soft bins the two
    whose centres are nearest, by nearness (the upper share in 1/255ths)."""
    bv = config.bins_v
    if config.value_blend == 0:
        return [(level * bv // 256, 1.0)]
    position = (level + 0.5) * bv / 256 - 0.5  # bin centres are the integers
    below = int(np.floor(position))
    blended = min(max((position - below - 0.5) / config.value_blend + 0.5, 0.0), 1.0)
    upper = round(blended * 255) / 255
    return [(min(max(below, 0), bv - 1), 1 - upper), (min(max(below + 1, 0), bv - 1), upper)]


@pytest.mark.parametrize(
    "parts, collapse, blend", [(1, False, 0.0), (2, True, 0.0), (4, True, 0.0),
                               (1, False, 1.0), (2, True, 1.0), (2, True, 0.5)]
)  # fmt: skip
def test_vectorised_histograms_equal_the_slow_reference(
    parts: int, collapse: bool, blend: float
) -> None:
    rng = np.random.default_rng(3)
    frame = rng.integers(0, 256, (60, 80, 3), dtype=np.uint8)
    config = ColorConfig(
        grid_cols=8, grid_rows=16, parts=parts, achromatic_collapse=collapse, value_blend=blend
    )
    # boxes inside, straddling the edges and fully outside the frame
    boxes = np.array(
        [[40.0, 30.0, 20.0, 30.0], [3.0, 5.0, 16.0, 24.0], [78.0, 58.0, 10.0, 12.0], [200, 9, 8, 8]]
    )
    luts = make_luts(config)
    region = frame[0:60, 0:80]
    grid = kernel_grid(config.grid_cols, config.grid_rows, parts=parts)
    fast = box_histograms(pad_bins(bin_image(region, luts), 216), (0, 0), boxes, grid, 216)
    slow = _slow_histograms(frame, boxes, config, parts)
    np.testing.assert_allclose(fast, slow, atol=1e-12)
    np.testing.assert_allclose(fast.sum(axis=2), 1.0)
    assert fast[3, :, -1] == pytest.approx(1.0)  # all outside
    # a sub-region bin image with its origin gives the same histograms for boxes inside it
    sub_bins = pad_bins(bin_image(frame[10:55, 20:70], luts), 216)
    sub = box_histograms(sub_bins, (20, 10), boxes[:1], grid, 216)
    np.testing.assert_allclose(sub, fast[:1])


@pytest.mark.parametrize("blend", [0.0, 0.5])
def test_a_grids_per_box_count_arrays_are_bounded_and_go_with_the_grid(blend: float) -> None:
    """A lock makes a new grid (the box's aspect); what `box_histograms` keeps for a grid
    (per box count) is freed with it, and a few box counts are kept at most."""
    rng = np.random.default_rng(5)
    luts = make_luts(ColorConfig(value_blend=blend))
    bins = pad_bins(bin_image(rng.integers(0, 256, (60, 80, 3), dtype=np.uint8), luts), 216)
    grid = kernel_grid(16, 32, aspect=0.4, parts=2)
    first = box_histograms(bins, (0, 0), np.tile([40.0, 30.0, 20.0, 30.0], (300, 1)), grid, 216)
    for n in range(1, 12):  # more box counts than are kept
        boxes = np.tile([40.0, 30.0, 20.0, 30.0], (n, 1))
        again = box_histograms(bins, (0, 0), boxes, grid, 216)
        np.testing.assert_array_equal(again, first[:n])
    assert len(grid._per_n) == _PER_GRID
    held = weakref.ref(grid._per_n[(11, 216)].weights)
    gone = weakref.ref(grid)
    del grid
    gc.collect()
    assert gone() is None and held() is None


def test_soft_histograms_of_many_boxes_are_made_in_passes_with_bounded_scratch() -> None:
    """A frame-wide scan's hundreds of boxes: the same histograms as box by box, and the
    scratch the grid keeps is for `_SOFT_CHUNK` boxes however many there are."""
    rng = np.random.default_rng(7)
    luts = make_luts(ColorConfig(value_blend=0.5))
    bins = pad_bins(bin_image(rng.integers(0, 256, (60, 80, 3), dtype=np.uint8), luts), 216)
    grid = kernel_grid(16, 32, aspect=0.4, parts=2)
    n = 2 * _SOFT_CHUNK + 17  # two whole passes and a part
    boxes = np.column_stack(
        [
            rng.uniform(0, 80, n),
            rng.uniform(0, 60, n),
            rng.uniform(6, 30, n),
            rng.uniform(10, 50, n),
        ]
    )
    together = box_histograms(bins, (0, 0), boxes, grid, 216)
    one_by_one = np.concatenate([box_histograms(bins, (0, 0), b[None], grid, 216) for b in boxes])
    np.testing.assert_allclose(together, one_by_one, atol=1e-12)
    kept = grid._per_n[(_SOFT_CHUNK, 216)]
    assert kept.soft_columns is not None and kept.soft_weights is not None
    visited = grid.sample_rows.size  # the samples of non-zero weight
    assert visited == np.count_nonzero(grid.weights) < 16 * 32
    assert kept.soft_columns.size == kept.soft_weights.size == 2 * _SOFT_CHUNK * visited
    assert (n, 216) not in grid._per_n


@pytest.mark.parametrize("blend", [1.0, 0.5, 0.0])
def test_a_shirt_on_a_value_bin_edge_is_the_same_colour_either_side_of_it(
    blend: float,
) -> None:
    """The same blue shirt at V 168 and, a little brighter, at V 176 (the hard edge between
    value bins 3 and 4 is at 170.7). With soft value bins he matches his model either side
    of the edge; with hard bins every pixel changes bin and he matches it not at all
    (synthetic:22)."""
    frame = np.full((120, 160, 3), 90, np.uint8)  # grey surroundings
    frame[30:90, 20:50] = (168, 84, 42)  # same hue and saturation, V 168 and 176
    frame[30:90, 110:140] = (176, 88, 44)
    likelihood = ColorLikelihood(ColorConfig(value_blend=blend), GmmConfig())
    there, brighter = np.array([[35.0, 60.0, 30.0, 60.0], [125.0, 60.0, 30.0, 60.0]])
    likelihood.init(frame, there)
    weighed = bhattacharyya(likelihood.histograms(frame, brighter[None, :]), likelihood.model)
    similarity = likelihood.similarity(frame, brighter)
    if blend > 0:
        assert weighed[0] > 0.9  # 0.98 with blend 1, 0.92 with 0.5
        assert similarity > 0.9
    else:
        assert weighed[0] < 0.05
        assert similarity < 0.05
    assert likelihood.similarity(frame, there) == pytest.approx(1.0)


def test_soft_value_bins_split_a_level_by_nearness_to_the_bin_centres() -> None:
    """Hand-computed: with 6 value bins the centres are at levels 20.8, 63.5, ...; level 168
    sits at (168.5 * 6 / 256) - 0.5 = 3.4492 bins, so 0.5508 of it goes to bin 3 and 0.4492
    (115/255) to bin 4; the levels at the ends stay whole in the end bins."""
    luts = make_luts(ColorConfig(value_blend=1.0))
    assert luts.value_upper is not None and luts.upper_share is not None
    assert (luts.value[168], luts.value_upper[168]) == (3, 4)
    assert luts.upper_share[168] == 115
    assert luts.value[0] == luts.value_upper[0] == 0
    assert luts.value[255] == luts.value_upper[255] == 5


def test_half_blended_value_bins_split_only_near_an_edge() -> None:
    """`value_blend = 0.5` (the default): the split ramps from 0 to 1 over the half bin
    round each edge. Level 168 is 0.0508 bins below the edge at 3.5, so the upper bin takes
    (0.4492 - 0.5) / 0.5 + 0.5 = 0.3984 of it (102/255); level 149, at 3.004 bins, is more
    than a quarter bin from either edge and stays whole in bin 3, as with hard bins."""
    luts = make_luts(ColorConfig(value_blend=0.5))
    assert luts.value_upper is not None and luts.upper_share is not None
    assert (luts.value[168], luts.value_upper[168], luts.upper_share[168]) == (3, 4, 102)
    assert (luts.value[149], luts.upper_share[149]) == (3, 0)
    hard = make_luts(ColorConfig(value_blend=0.0))
    assert hard.upper_share is None  # the seed's bins, one plane


def test_kernel_weighs_the_centre_most() -> None:
    grid = kernel_grid(16, 32)
    assert grid.weights.sum() == pytest.approx(1.0)
    assert grid.weights[16, 8] == grid.weights.max()
    assert grid.weights[0, 0] == 0.0  # corner lies outside the inscribed ellipse
    seed_grid = kernel_grid(16, 32, "diagonal", aspect=0.5)
    assert seed_grid.weights.min() > 0  # the seed's a = sqrt(w^2+h^2) never reaches zero


def test_a_wide_box_s_top_kernel_is_no_wider_than_top_max_aspect() -> None:
    """A box of aspect 0.8 with top_max_aspect 0.4: the top stripe's kernel spans the middle
    half of the box's width (|u| < 0.25 box widths) with the full kernel's profile, its sides
    weigh nothing; the bottom stripe (legs apart) keeps the inscribed ellipse. Boxes no wider,
    a one-part grid and a limit of 0 keep the plain kernel."""
    plain = kernel_grid(16, 32, parts=2)
    wide = kernel_grid(16, 32, aspect=0.8, parts=2, top_max_aspect=0.4)
    top, bottom = wide.part == 0, wide.part == 1
    sides = np.abs(wide.u) > 0.25
    assert wide.weights[np.ix_(top, sides)].sum() == 0.0
    assert wide.weights[np.ix_(top, ~sides)].min(axis=1).max() > 0
    half = kernel_grid(8, 32, parts=2).weights[8]
    middle = wide.weights[8, ~sides]
    np.testing.assert_allclose(middle / middle.max(), half / half.max())
    np.testing.assert_allclose(wide.weights[bottom], plain.weights[bottom])
    for part in range(2):
        assert wide.weights[wide.part == part].sum() == pytest.approx(1.0)
    for grid in (
        kernel_grid(16, 32, aspect=0.4, parts=2, top_max_aspect=0.4),
        kernel_grid(16, 32, aspect=0.8, parts=2, top_max_aspect=0.0),
    ):
        np.testing.assert_array_equal(grid.weights, plain.weights)
    one_part = kernel_grid(16, 32, aspect=0.8, parts=1, top_max_aspect=0.4)
    np.testing.assert_array_equal(one_part.weights, kernel_grid(16, 32).weights)


def test_likelihood_peaks_at_the_true_box() -> None:
    scene = Scene()
    frame = scene.frame(0)
    x, y, w, h = scene.truth(0)
    truth = np.array([x + w / 2, y + h / 2, w, h])
    likelihood = ColorLikelihood(ColorConfig(), GmmConfig())
    likelihood.init(frame, truth)
    shifts = np.arange(-12, 13, 2.0)
    dx, dy = np.meshgrid(shifts, shifts)
    boxes = np.column_stack(
        [truth[0] + dx.ravel(), truth[1] + dy.ravel(), np.full(dx.size, w), np.full(dx.size, h)]
    )
    log_l = likelihood.log_likelihood(frame, boxes)
    best = boxes[np.argmax(log_l)]
    assert abs(best[0] - truth[0]) <= 2 and abs(best[1] - truth[1]) <= 2
    # and over scale: the true size beats shrunken and grown boxes
    scales = np.array([0.6, 0.8, 1.0, 1.25, 1.6])
    sized = np.column_stack([np.full(5, truth[0]), np.full(5, truth[1]), w * scales, h * scales])
    assert np.argmax(likelihood.log_likelihood(frame, sized)) == 2
    assert likelihood.similarity(frame, truth) == pytest.approx(1.0)
    assert likelihood.similarity(frame, truth + np.array([100, 60, 0, 0])) < 0.5


def test_bhattacharyya_of_identical_and_disjoint_histograms() -> None:
    q = np.array([[0.5, 0.5, 0.0]])
    p = np.array([[[0.5, 0.5, 0.0, 0.0]], [[0.0, 0.0, 1.0, 0.0]], [[0.0, 0.0, 0.0, 1.0]]])
    np.testing.assert_allclose(bhattacharyya(p, q), [1.0, 0.0, 0.0])


def test_background_weights_downweight_common_ring_colours() -> None:
    ring = np.array([0.7, 0.25, 0.05, 0.0])
    v = background_weights(ring, floor=0.0)
    np.testing.assert_allclose(v, [0.05 / 0.7, 0.05 / 0.25, 1.0, 1.0])


def test_gmm_update_matches_a_hand_computed_example() -> None:
    config = GmmConfig(alpha=0.1, beta=0.2, initial_sigma=0.5, diff_threshold=0.3)
    model = GmmTargetModel(np.array([0.6, 0.4]), config)
    np.testing.assert_allclose(model.model, [0.6, 0.4])
    # bin 0 observes 0.8: |0.8-0.6| < 0.3 gate, first component (stable order) fits (< 1.5)
    # mu0 = 0.9*0.6 + 0.1*0.8 = 0.62; sigma0 = sqrt(0.9*0.25 + 0.1*(0.8-0.62)^2)
    # pi = (0.8*1/3 + 0.2, 0.8/3, 0.8/3); bin 1 observes 0.2 likewise: mu0 = 0.38
    out = model.update(np.array([0.8, 0.2]))
    sigma0 = np.sqrt(0.9 * 0.25 + 0.1 * 0.18**2)
    np.testing.assert_allclose(model.mu[0], [0.62, 0.6, 0.6])
    np.testing.assert_allclose(model.mu[1], [0.38, 0.4, 0.4])
    np.testing.assert_allclose(model.sigma[0], [sigma0, 0.5, 0.5])
    np.testing.assert_allclose(model.pi[0], [0.8 / 3 + 0.2, 0.8 / 3, 0.8 / 3])
    # q = 0.6*mu_a + 0.25*mu_b + 0.15*mu_c, then normalised over the bins
    raw = np.array([0.6 * 0.62 + 0.4 * 0.6, 0.6 * 0.38 + 0.4 * 0.4])
    np.testing.assert_allclose(out, raw / raw.sum())
    # a jump larger than diff_threshold leaves the bin's mixture alone
    before = model.mu.copy()
    model.update(np.array([0.1, 0.9]))
    np.testing.assert_allclose(model.mu, before)


def test_gmm_replaces_the_weakest_component_when_nothing_fits() -> None:
    config = GmmConfig(initial_sigma=0.01, diff_threshold=0.5, beta=0.1)
    model = GmmTargetModel(np.array([0.5, 0.5]), config)
    model.update(np.array([0.5, 0.5]))  # component 0 gets the top weight
    model.update(np.array([0.7, 0.3]))  # 0.2 away: > 3 sigma everywhere
    assert model.mu[0, 2] == pytest.approx(0.7)
    assert model.sigma[0, 2] == pytest.approx(0.01)
    np.testing.assert_allclose(model.pi.sum(axis=1), 1.0)


def test_colour_tracker_runs_on_grey_frames() -> None:
    """Thermal / grey input (H x W and H x W x 1) is tracked, not a crash."""
    from ptzd.vision.config import TrackerConfig
    from ptzd.vision.tracking import TrackState, make_tracker

    rng = np.random.default_rng(3)
    base = rng.integers(20, 60, size=(120, 160), dtype=np.uint8)
    for add_axis in (False, True):
        tracker = make_tracker(TrackerConfig(kind="color", num_particles=50))
        frames = []
        for t in range(6):
            frame = base.copy()
            frame[40:80, 30 + 4 * t : 50 + 4 * t] = 230  # a warm body moving right
            frames.append(np.ascontiguousarray(frame[:, :, None] if add_axis else frame))
        tracker.init(frames[0], (30.0, 40.0, 20.0, 40.0))
        for frame in frames[1:]:
            result = tracker.update(frame)
        assert result.state is TrackState.TRACKING
        assert abs(result.box[0] - 50.0) < 8.0


def test_background_weights_of_a_vanishing_ring_share_are_one_without_warnings() -> None:
    import warnings

    from ptzd.vision.color import background_weights

    ring = np.array([0.5, 1e-310, 0.0, 0.2])  # a share decayed to a subnormal number
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        weights = background_weights(ring)
    assert weights[1] == 1.0 and weights[2] == 1.0
    assert weights[0] < weights[3] < 1.0  # commoner around the target: counts less


def test_part_similarities_tell_half_a_match_from_a_whole_one() -> None:
    from tests.vision_helpers import background, draw_person

    box = (100.0, 60.0, 30.0, 80.0)
    centre = np.array([115.0, 100.0, 30.0, 80.0])
    target = background(320, 240, 0)[:240, :320].copy()
    draw_person(target, box, (40, 40, 200), (160, 60, 20))
    impostor = background(320, 240, 0)[:240, :320].copy()
    draw_person(impostor, box, (40, 160, 40), (160, 60, 20))  # same trousers, green top
    likelihood = ColorLikelihood(ColorConfig(parts=2), GmmConfig())
    likelihood.init(target, centre)
    whole = likelihood.part_similarities(target, centre)
    half = likelihood.part_similarities(impostor, centre)
    np.testing.assert_allclose(whole, [1.0, 1.0])
    assert half[0] < 0.5 < 0.9 < half[1]  # top to bottom
    assert likelihood.similarity(impostor, centre) == pytest.approx(half.mean())


def test_weighted_confidence_discounts_background_in_the_box_not_another_person() -> None:
    from tests.vision_helpers import background, draw_person

    hedge = (40, 150, 60)  # BGR: most of what is around the target
    box = (100.0, 60.0, 30.0, 80.0)
    centre = np.array([115.0, 100.0, 30.0, 80.0])
    scene = background(320, 240, 0)[:240, :320].copy()
    scene[30:170, 60:170] = hedge
    target = scene.copy()
    draw_person(target, box, (40, 40, 200), (160, 60, 20))
    behind = target.copy()
    behind[60:75, 95:135] = hedge  # the hedge comes into the top of his box
    impostor = scene.copy()
    draw_person(impostor, box, (200, 120, 40), (160, 60, 20))  # same trousers, blue top
    plain = ColorLikelihood(ColorConfig(parts=2, weighted_confidence=False), GmmConfig())
    weighted = ColorLikelihood(ColorConfig(parts=2, weighted_confidence=True), GmmConfig())
    for likelihood in (plain, weighted):
        likelihood.init(target, centre)
    np.testing.assert_allclose(weighted.part_similarities(target, centre), [1.0, 1.0])
    top_plain = plain.part_similarities(behind, centre)[0]
    top_weighted = weighted.part_similarities(behind, centre)[0]
    assert top_plain < 0.85 and top_weighted > 0.95 > top_plain + 0.1
    # another shirt is not background: it still fails the part test
    assert weighted.part_similarities(impostor, centre)[0] < 0.5
    # the part of a box outside the frame still costs what it did
    edge = scene.copy()
    draw_person(edge, (-15.0, 60.0, 30.0, 80.0), (40, 40, 200), (160, 60, 20))
    cut = np.array([0.0, 100.0, 30.0, 80.0])
    half = weighted.similarity(edge, cut)
    assert half < 0.8
    assert half == pytest.approx(plain.similarity(edge, cut), abs=0.05)


@pytest.mark.parametrize("top_max_aspect", [0.0, 0.45])
def test_what_stands_beside_a_wide_box_s_top_does_not_count(top_max_aspect: float) -> None:
    """A box 0.7 of its height wide round a figure whose legs are apart: a brown bench
    beside its shoulders, inside the box, changes the box's score with the kernel inscribed
    in the box (0), and not at all with the top stripe's kernel limited to 0.45 of the
    height (the bench lies outside it); the legs, at the sides of the bottom stripe, count
    either way."""
    frame = np.full((200, 200, 3), 128, np.uint8)  # grey paving
    frame[60:100, 90:110] = (40, 40, 40)  # dark top
    frame[100:140, 82:92] = frame[100:140, 108:118] = (150, 60, 20)  # blue legs apart
    box = np.array([100.0, 100.0, 56.0, 80.0])  # aspect 0.7
    config = ColorConfig(top_max_aspect=top_max_aspect, background_weighting=False)
    likelihood = ColorLikelihood(config, GmmConfig())
    likelihood.init(frame, box)
    with_bench = frame.copy()
    with_bench[62:98, 74:82] = with_bench[62:98, 118:126] = (40, 90, 160)  # wood at his sides
    without_legs = frame.copy()
    without_legs[100:140, 82:92] = 128
    boxes = box[None, :]
    before = likelihood.log_likelihood(frame, boxes)[0]
    bench = likelihood.log_likelihood(with_bench, boxes)[0]
    if top_max_aspect:
        assert bench == before
    else:
        assert bench < before - 1.0
    assert likelihood.log_likelihood(without_legs, boxes)[0] < before - 1.0  # legs count
