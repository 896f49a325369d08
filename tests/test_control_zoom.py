"""Nine-region FOV hysteresis and the zoom-layer controller (seed eqs. 32-38)."""

from __future__ import annotations

import pytest

from ptzd.control.config import ZoomConfig
from ptzd.control.regions import AxisBand, NineRegionFov
from ptzd.control.zoom import Box, ZoomController, ZoomDirection, seed_resize

SIZE = (640, 480)


def test_stop_band_has_hysteresis() -> None:
    band = AxisBand(0.1, 0.2)
    assert band.update(0.15) == 0  # starts stopped, 0.15 is inside the leave threshold
    assert band.update(0.21) == 1  # leaves the stop band only past 0.2
    assert band.update(0.15) == 1  # keeps moving until inside the enter threshold
    assert band.update(0.09) == 0
    assert band.update(-0.19) == 0
    assert band.update(-0.25) == -1


def test_dead_zone_never_moves() -> None:
    fov = NineRegionFov(0.1, 0.2)
    for x in (-0.099, 0.0, 0.05, 0.15, -0.18):
        region = fov.update(x, -x)
        assert region.is_stop and region.index == 4


def test_nine_regions_map_to_directions() -> None:
    fov = NineRegionFov(0.1, 0.2)
    assert fov.update(-0.5, -0.5).index == 0  # top-left
    fov.reset()
    assert fov.update(0.5, 0.5).index == 8  # bottom-right
    fov.reset()
    region = fov.update(0.5, 0.0)
    assert (region.column, region.row) == (1, 0)


def test_hysteresis_requires_enter_below_leave() -> None:
    with pytest.raises(ValueError):
        AxisBand(0.2, 0.2)


def test_seed_resize_keeps_aspect_ratio() -> None:
    cfg = ZoomConfig(size_measure="seed")
    desired = (40.0, 120.0)  # ratio 1/3
    assert seed_resize(Box(0, 0, 40, 120), *desired, cfg) is None
    assert seed_resize(Box(0, 0, 43, 130), *desired, cfg) is None  # inside [0.9, 1.1]
    small = seed_resize(Box(100, 100, 30, 90), *desired, cfg)  # w < lower_w: eqs. 35-36
    assert small is not None
    box, factor = small
    assert box.w == pytest.approx(40 * 0.9 * 1.1)
    assert box.h == pytest.approx(box.w * 3)
    assert (box.cx, box.cy) == (115, 145)  # same centre
    assert factor == pytest.approx(box.w / 30)
    tall = seed_resize(Box(0, 0, 40, 150), *desired, cfg)  # h > upper_h: eqs. 37-38
    assert tall is not None
    assert tall[0].h == pytest.approx(120 * 1.1 * 0.9)
    assert tall[0].w == pytest.approx(tall[0].h / 3)
    assert tall[1] < 1
    narrow = seed_resize(Box(0, 0, 30, 120), *desired, cfg)  # seed: width is tested first
    assert narrow is not None and narrow[1] > 1
    by_height = ZoomConfig(size_measure="height")
    assert seed_resize(Box(0, 0, 30, 120), *desired, by_height) is None  # width swings ignored
    short = seed_resize(Box(0, 0, 40, 100), *desired, by_height)
    assert short is not None
    assert short[0].h == pytest.approx(120 * 0.9 * 1.1) and short[0].w == pytest.approx(39.6)


def _centred(w: float, h: float) -> Box:
    return Box(SIZE[0] / 2 - w / 2, SIZE[1] / 2 - h / 2, w, h)


def test_zoom_in_when_small_slow_and_central_counts_layers() -> None:
    zoom = ZoomController(ZoomConfig(confirm_s=0.0, min_dwell_s=0.0))
    zoom.set_desired(40, 120)
    step = zoom.update(_centred(30, 90), SIZE, speed=0.0, now=0.0)
    assert step is not None and step.direction == ZoomDirection.IN
    assert step.layer == 1 and zoom.layer == 1
    assert step.factor == pytest.approx(39.6 / 30)
    assert step.box_after.h == pytest.approx(39.6 * 3)
    step = zoom.update(_centred(30, 90), SIZE, speed=0.0, now=1.0)
    assert step is not None and zoom.layer == 2
    # too big: zoom out, layer back down
    step = zoom.update(_centred(50, 150), SIZE, speed=0.0, now=20.0)
    assert step is not None and step.direction == ZoomDirection.OUT and zoom.layer == 1
    assert step.factor < 1


def test_no_zoom_in_when_fast_or_off_centre_or_would_not_fit() -> None:
    zoom = ZoomController(ZoomConfig(confirm_s=0.0, min_dwell_s=0.0))
    zoom.set_desired(40, 120)
    assert zoom.update(_centred(30, 90), SIZE, speed=0.3, now=0.0) is None  # not slow
    off = Box(420, 200, 30, 90)  # centre well right of the central region
    assert zoom.update(off, SIZE, speed=0.0, now=0.0) is None
    huge = ZoomController(ZoomConfig(confirm_s=0.0, min_dwell_s=0.0))
    huge.set_desired(120, 360)  # would fill the view after the step
    assert huge.update(_centred(100, 300), SIZE, speed=0.0, now=0.0) is None
    assert zoom.layer == 0 and huge.layer == 0


def test_zoom_out_near_edge_or_fast() -> None:
    zoom = ZoomController(ZoomConfig(confirm_s=0.0, min_dwell_s=0.0))
    zoom.set_desired(40, 120)
    edge = zoom.update(Box(2, 180, 40, 120), SIZE, speed=0.0, now=0.0)
    assert edge is not None and edge.direction == ZoomDirection.OUT and edge.reason == "near edge"
    fast = zoom.update(_centred(40, 120), SIZE, speed=1.0, now=5.0)
    assert fast is not None and fast.direction == ZoomDirection.OUT and fast.reason == "fast"
    assert zoom.layer == -2


def test_confirm_dwell_and_reversal_guard_prevent_hunting() -> None:
    cfg = ZoomConfig(confirm_s=0.5, min_dwell_s=1.5, reversal_guard_s=10.0)
    zoom = ZoomController(cfg)
    zoom.set_desired(40, 120)
    small, big = _centred(30, 90), _centred(50, 150)
    assert zoom.update(small, SIZE, 0.0, now=0.0) is None  # not confirmed yet
    assert zoom.update(small, SIZE, 0.0, now=0.6) is not None  # confirmed: layer 1
    assert zoom.update(small, SIZE, 0.0, now=1.5) is None  # dwell
    assert zoom.update(big, SIZE, 0.0, now=2.0) is None  # confirming
    assert zoom.update(big, SIZE, 0.0, now=2.6) is not None  # first reversal allowed
    assert zoom.reversals == 1
    # The target keeps asking to zoom back in: no second reversal until 10 s after the first.
    t = 2.7
    while t < 12.5:
        assert zoom.update(small, SIZE, 0.0, now=t) is None, t
        t += 0.1
    assert zoom.reversals == 1 and zoom.layer == 0
    assert zoom.update(small, SIZE, 0.0, now=12.7) is not None  # after 10 s it may reverse
    assert zoom.reversals == 2


def test_no_step_and_no_layer_at_the_lens_end_stops() -> None:
    zoom = ZoomController(ZoomConfig(confirm_s=0.0, min_dwell_s=0.0))
    zoom.set_desired(40, 120)
    assert zoom.update(_centred(30, 90), SIZE, 0.0, now=0.0, can_in=False) is None
    assert zoom.update(_centred(50, 150), SIZE, 0.0, now=1.0, can_out=False) is None
    assert zoom.layer == 0


def test_layer_limits() -> None:
    zoom = ZoomController(ZoomConfig(confirm_s=0.0, min_dwell_s=0.0, max_layer=1))
    zoom.set_desired(40, 120)
    assert zoom.update(_centred(30, 90), SIZE, 0.0, now=0.0) is not None
    assert zoom.update(_centred(30, 90), SIZE, 0.0, now=1.0) is None
    assert zoom.layer == 1
