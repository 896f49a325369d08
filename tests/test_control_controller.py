"""PtzController: regions to directions, staleness, lost policy, zoom pulses, FOV gain, latency."""

from __future__ import annotations

import math

import pytest

from ptzd.control.config import ControlConfig, LostConfig, ZoomConfig
from ptzd.control.controller import STOP, PtzController, TrackInput
from ptzd.control.egomotion import rate_for_byte
from ptzd.control.zoom import Box
from ptzd.pelco.codec import Motion, Preset, PresetAction, Zoom
from ptzd.vision.tracking import TrackState

SIZE = (640, 480)
TARGET = Box(300, 180, 40, 120)  # centred, the desired size


def _track(box: Box, t: float, *, state: TrackState = TrackState.TRACKING,
           velocity: tuple[float, float] = (0.0, 0.0)) -> TrackInput:  # fmt: skip
    return TrackInput(box, velocity, state, 0.9, t)


def _controller(**overrides: object) -> PtzController:
    ctl = PtzController(ControlConfig.model_validate(overrides), SIZE)
    ctl.acquire(TARGET)
    return ctl


def test_directions_follow_the_nine_regions() -> None:
    ctl = _controller()
    right_low = Box(560, 380, 40, 90)  # right of and below the centre
    decision = ctl.update(_track(right_low, 0.0), now=0.0, hfov=60.0)
    assert decision.mode == "track"
    assert decision.region is not None and decision.region.index == 8
    assert decision.motion.pan > 0  # pan right
    assert decision.motion.tilt < 0  # tilt down
    ctl = _controller()
    left_high = Box(20, 10, 40, 90)
    motion = ctl.update(_track(left_high, 0.0), now=0.0, hfov=60.0).motion
    assert motion.pan < 0 and motion.tilt > 0


def test_stop_region_gives_stop() -> None:
    ctl = _controller()
    decision = ctl.update(_track(Box(310, 190, 40, 110), 0.0), now=0.0, hfov=60.0)
    assert decision.motion == STOP
    assert decision.region is not None and decision.region.is_stop


def test_a_stale_track_never_moves_the_camera() -> None:
    ctl = _controller(max_track_age_s=0.3)
    far_right = Box(600, 180, 40, 120)
    assert ctl.update(_track(far_right, 0.0), now=0.1, hfov=60.0).motion.pan > 0
    for now in (0.31, 0.5, 2.0, 60.0):
        decision = ctl.update(_track(far_right, 0.0), now=now, hfov=60.0)
        assert decision.motion == STOP and decision.mode == "stale"
    assert ctl.update(None, now=61.0, hfov=60.0).motion == STOP


def test_stale_frames_stop_a_widening_dome_without_a_target() -> None:
    # the stream stalls while the dome zooms out to find someone (seen in the CI soak's
    # stream-stall fault: zoom OUT on the wire 3.4 s into a 6 s stall)
    ctl = _controller(max_track_age_s=0.5, lost=LostConfig(widen_s=5.0))
    ctl.go_home(10.0)
    assert ctl.update(None, now=10.2, hfov=20.0, frame_time=10.1).mode == "widen"
    stalled = ctl.update(None, now=10.7, hfov=25.0, frame_time=10.1)
    assert stalled.motion == STOP and stalled.mode == "stale"
    # frames again (widen_s not over): the widening resumes, and ends as before
    assert ctl.update(None, now=12.0, hfov=25.0, frame_time=11.9).mode == "widen"
    assert ctl.update(None, now=15.1, hfov=60.0, frame_time=15.0).mode == "idle"


def test_lost_stops_holds_then_goes_home_once() -> None:
    ctl = _controller(lost=LostConfig(follow_lost_s=0.0, hold_s=2.0, home_preset=7))
    decisions = [
        ctl.update(_track(TARGET, t, state=TrackState.LOST), now=t, hfov=60.0)
        for t in (0.0, 1.0, 1.9)
    ]
    assert all(d.motion == STOP and d.preset is None and d.mode == "lost" for d in decisions)
    home = ctl.update(_track(TARGET, 2.1, state=TrackState.LOST), now=2.1, hfov=60.0)
    assert home.mode == "home" and home.preset == Preset(PresetAction.GOTO, 7)
    again = ctl.update(_track(TARGET, 3.0, state=TrackState.LOST), now=3.0, hfov=60.0)
    assert again.preset is None and again.motion == STOP


def test_go_home_on_request_once_per_loss_and_never_without_a_preset() -> None:
    ctl = _controller(lost=LostConfig(hold_s=60.0, home_preset=4))
    ctl.update(_track(TARGET, 0.0, state=TrackState.LOST), now=0.0, hfov=60.0)
    # acquisition gave up before the hold ran out: home now, once
    assert ctl.go_home(0.0) == Preset(PresetAction.GOTO, 4)
    assert ctl.zoom_layer == 0
    assert ctl.go_home(0.0) is None
    later = ctl.update(_track(TARGET, 61.0, state=TrackState.LOST), now=61.0, hfov=60.0)
    assert later.preset is None  # the lost policy does not send it a second time
    # a new target re-arms it
    ctl.acquire(TARGET)
    assert ctl.go_home(0.0) == Preset(PresetAction.GOTO, 4)
    assert _controller().go_home(0.0) is None  # home_preset 0: there is no home


def test_occluded_follows_the_coasting_box_without_zooming_or_holds() -> None:
    occluded_right = _track(Box(600, 180, 20, 60), 0.0, state=TrackState.OCCLUDED)
    ctl = _controller(zoom=ZoomConfig(confirm_s=0.0))
    coast = ctl.update(occluded_right, now=0.0, hfov=60.0)
    assert coast.mode == "coast" and coast.motion.pan > 0
    assert coast.motion.zoom == Zoom.NONE and coast.zoom_step is None  # small, but no zoom
    held = _controller(lost=LostConfig(follow_occluded=False)).update(
        occluded_right, now=0.0, hfov=60.0
    )
    assert held.motion == STOP and held.mode == "hold"


def test_a_lost_track_is_followed_for_follow_lost_s_then_stopped() -> None:
    # a walker hidden behind a column for longer than the tracker's occlusion limit: the
    # dome follows the coasting box for follow_lost_s more, without zooming, then stops
    lost_right = [_track(Box(600, 180, 20, 60), t, state=TrackState.LOST) for t in (0, 0.5, 1.1)]
    ctl = _controller(zoom=ZoomConfig(confirm_s=0.0), lost=LostConfig(follow_lost_s=1.0))
    decisions = [ctl.update(track, now=track.capture_time, hfov=60.0) for track in lost_right]
    assert [d.mode for d in decisions] == ["coast", "coast", "lost"]
    assert all(d.motion.pan > 0 and d.zoom_step is None for d in decisions[:2])
    assert decisions[2].motion == STOP
    # the hold before going home counts from the loss, not from the end of the following
    homing = _controller(lost=LostConfig(follow_lost_s=1.0, hold_s=2.0, home_preset=3))
    modes = [homing.update(_track(TARGET, t, state=TrackState.LOST), now=t, hfov=60.0).mode
             for t in (0.0, 1.5, 2.1)]  # fmt: skip
    assert modes == ["coast", "lost", "home"]
    # the default, and with follow_occluded off: stop at once
    for lost in (LostConfig(follow_lost_s=0.0), LostConfig(follow_occluded=False)):
        first = _controller(lost=lost).update(lost_right[0], now=0.0, hfov=60.0)
        assert first.mode == "lost" and first.motion == STOP


def test_narrower_fov_turns_slower() -> None:
    off = Box(520, 180, 40, 120)
    wide = _controller().update(_track(off, 0.0), now=0.0, hfov=60.0).motion.pan
    narrow = _controller().update(_track(off, 0.0), now=0.0, hfov=10.0).motion.pan
    assert wide > narrow > 0


def test_latency_compensation_predicts_the_target() -> None:
    # Centred now, but moving right at 400 px/s and the frame is 0.2 s old: act as if right.
    ctl = _controller(lead_s=0.0)
    decision = ctl.update(_track(TARGET, 0.0, velocity=(400.0, 0.0)), now=0.2, hfov=60.0)
    assert decision.predicted is not None and decision.predicted[0] == pytest.approx(400.0)
    assert decision.motion.pan > 0
    still = _controller(lead_s=0.0).update(_track(TARGET, 0.0), now=0.2, hfov=60.0)
    assert still.motion.pan == 0


def test_zoom_step_is_a_timed_pulse_and_counts_a_layer() -> None:
    ctl = _controller(zoom=ZoomConfig(confirm_s=0.0, min_dwell_s=5.0, log_rate=0.5))
    small = Box(305, 195, 30, 90)  # 0.75 x desired, centred and still
    first = ctl.update(_track(small, 0.0), now=0.0, hfov=40.0)
    assert first.zoom_step is not None and first.motion.zoom == Zoom.IN
    assert ctl.zoom_layer == 1
    duration = abs(math.log(first.zoom_step.factor)) / 0.5
    during = ctl.update(_track(small, duration / 2), now=duration / 2, hfov=40.0)
    assert during.motion.zoom == Zoom.IN and during.zoom_step is None
    after = ctl.update(_track(small, duration + 0.01), now=duration + 0.01, hfov=40.0)
    assert after.motion.zoom == Zoom.NONE and ctl.zoom_layer == 1  # dwell: no second step yet


def test_zoom_in_waits_for_a_confident_track_zoom_out_does_not() -> None:
    # a half-hidden walker's box shrinks and its confidence drops: no zoom in on it
    gated = ZoomConfig(confirm_s=0.0, in_min_confidence=0.8)
    small = Box(305, 195, 30, 90)  # 0.75 x desired, centred and still
    unsure = TrackInput(small, (0.0, 0.0), TrackState.TRACKING, 0.75, 0.0)
    ctl = _controller(zoom=gated)
    assert ctl.update(unsure, now=0.0, hfov=40.0).motion == STOP and ctl.zoom_layer == 0
    sure = TrackInput(small, (0.0, 0.0), TrackState.TRACKING, 0.85, 0.1)
    assert ctl.update(sure, now=0.1, hfov=40.0).motion.zoom == Zoom.IN and ctl.zoom_layer == 1
    big = Box(290, 150, 60, 180)  # 1.5 x desired: out, however unsure
    ctl = _controller(zoom=gated)
    out = ctl.update(TrackInput(big, (0.0, 0.0), TrackState.TRACKING, 0.5, 0.0), 0.0, 40.0)
    assert out.motion.zoom == Zoom.OUT and ctl.zoom_layer == -1
    ungated = _controller(zoom=ZoomConfig(confirm_s=0.0, in_min_confidence=0.0))
    assert ungated.update(unsure, now=0.0, hfov=40.0).motion.zoom == Zoom.IN


def test_zoom_in_waits_when_the_box_shrank_faster_than_a_person_does() -> None:
    # a box collapsing onto the torso of a walker behind a lamp post: no zoom in on it until
    # it has been that small for in_height_window_s; a zoom step does not count as a shrink
    zoom = ZoomConfig(confirm_s=0.0, in_height_window_s=3.0, in_min_height_share=0.75)
    tall, collapsed = TARGET, Box(310, 210, 20, 66)  # 1.0 and 0.55 x desired, centred
    ctl = _controller(zoom=zoom)
    for i in range(10):  # 1 s at the desired height: inside the band, no step
        assert ctl.update(_track(tall, i * 0.1), now=i * 0.1, hfov=40.0).zoom_step is None
    for t in (1.0, 2.0, 3.9):  # the tall box is still within 3 s: held
        assert ctl.update(_track(collapsed, t), now=t, hfov=40.0).zoom_step is None
    step = ctl.update(_track(collapsed, 4.05), now=4.05, hfov=40.0).zoom_step
    assert step is not None and step.direction > 0  # small for 3 s: a real size now
    # the same collapse without the guard zooms in at once
    ctl = _controller(zoom=zoom.model_copy(update={"in_height_window_s": 0.0}))
    ctl.update(_track(tall, 0.0), now=0.0, hfov=40.0)
    assert ctl.update(_track(collapsed, 1.0), now=1.0, hfov=40.0).zoom_step is not None
    # heights are angles: the same target after a zoom out (half the pixels at twice the
    # FOV's tangent) is not a shrink, and a step in on it is taken straight away
    ctl = _controller(zoom=zoom)
    ctl.update(_track(tall, 0.0), now=0.0, hfov=20.0)
    wide = math.degrees(2 * math.atan(2 * math.tan(math.radians(10.0))))
    assert ctl.update(_track(collapsed, 0.5), now=0.5, hfov=wide).zoom_step is not None
    # unconfident boxes are not remembered: a blurred, oversized one does not hold zoom in
    ctl = _controller(zoom=zoom)
    tall_unsure = TrackInput(Box(300, 175, 44, 130), (0.0, 0.0), TrackState.TRACKING, 0.5, 0.0)
    assert ctl.update(tall_unsure, now=0.0, hfov=40.0).zoom_step is None  # in the band
    assert ctl.update(_track(collapsed, 2.0), now=2.0, hfov=40.0).zoom_step is not None


def test_zoom_in_waits_while_the_box_grows_back() -> None:
    # synthetic:18: the box collapsed onto a walker's upper body behind a passer-by and grew
    # back slowly; a step in on the half-grown box made the walker 1.3x the desired size
    zoom = ZoomConfig(
        confirm_s=0.0, in_height_window_s=3.0, in_min_height_share=0.75, in_max_growth=0.2
    )
    tall, collapsed = TARGET, Box(310, 210, 20, 66)  # 1.0 and 0.55 x desired, centred
    growing = Box(306, 198, 28, 84)  # 0.7 x desired: still too small, 1.27 x the collapse
    for guarded in (True, False):
        config = zoom if guarded else zoom.model_copy(update={"in_max_growth": 0.0})
        ctl = _controller(zoom=config)
        for i in range(10):  # 1 s at the desired height
            ctl.update(_track(tall, i * 0.1), now=i * 0.1, hfov=40.0)
        for t in (1.0, 2.0, 3.9):  # collapsed: held by the height share
            assert ctl.update(_track(collapsed, t), now=t, hfov=40.0).zoom_step is None
        step = ctl.update(_track(growing, 4.05), now=4.05, hfov=40.0).zoom_step
        if not guarded:
            assert step is not None and step.direction > 0  # stepped in on the half-grown box
            continue
        assert step is None
        for t in (5.0, 6.0, 6.85):  # the collapsed heights are still within 3 s: held
            assert ctl.update(_track(growing, t), now=t, hfov=40.0).zoom_step is None
        step = ctl.update(_track(growing, 6.95), now=6.95, hfov=40.0).zoom_step
        assert step is not None and step.direction > 0  # steady for 3 s: a real size now


def test_stale_track_aborts_a_zoom_pulse() -> None:
    ctl = _controller(zoom=ZoomConfig(confirm_s=0.0), max_track_age_s=0.2)
    assert ctl.update(_track(Box(305, 195, 30, 90), 0.0), now=0.0, hfov=40.0).motion.zoom == Zoom.IN
    assert ctl.update(_track(Box(305, 195, 30, 90), 0.0), now=0.3, hfov=40.0).motion == Motion()


def test_feedforward_turns_with_a_moving_target_inside_the_stop_band() -> None:
    ctl = _controller()
    hfov = 30.0
    focal = SIZE[0] / 2 / math.tan(math.radians(hfov) / 2)
    v = 60.0  # px/s to the right and down, the target's own motion
    decision = ctl.update(_track(TARGET, 0.0, velocity=(v, v)), now=0.0, hfov=hfov)
    assert decision.region is not None and decision.region.is_stop  # no correction...
    expected = math.degrees(v / focal)  # ...but the target's own angular rate
    pan = rate_for_byte(decision.motion.pan, ctl.config.dome)
    tilt = rate_for_byte(decision.motion.tilt, ctl.config.dome, tilt=True)
    assert pan == pytest.approx(expected, rel=0.07)  # one speed step of the curve is ~11 %
    assert tilt == pytest.approx(-expected, rel=0.07)  # moving down: tilt down
    # standing still (below feedforward_min_deg_s), or with the seed's pure PID: stop
    assert ctl.update(_track(TARGET, 0.1, velocity=(0.5, 0.0)), now=0.1, hfov=hfov).motion == STOP
    seed = _controller(feedforward=0.0)
    assert seed.update(_track(TARGET, 0.0, velocity=(v, v)), now=0.0, hfov=hfov).motion == STOP


def test_feedforward_adds_to_the_correction_and_lets_a_returning_target_come() -> None:
    right = Box(520, 180, 40, 120)  # right of the stop band
    still = _controller().update(_track(right, 0.0), now=0.0, hfov=30.0).motion.pan
    along = _controller().update(_track(right, 0.0, velocity=(80.0, 0.0)), now=0.0, hfov=30.0)
    assert along.motion.pan > still > 0  # running away: correction plus its own rate
    back = _controller().update(_track(right, 0.0, velocity=(-400.0, 0.0)), now=0.0, hfov=30.0)
    assert back.motion.pan == 0  # coming back to the centre faster than we would turn


def test_feedforward_needs_a_reported_pose_unless_told_otherwise() -> None:
    moving = TrackInput(TARGET, (60.0, 0.0), TrackState.TRACKING, 0.9, 0.0, pose_reported=False)
    assert _controller().update(moving, now=0.0, hfov=30.0).motion == STOP
    trusting = _controller(feedforward_dead_reckoned=True)
    assert trusting.update(moving, now=0.0, hfov=30.0).motion.pan > 0


def test_feedforward_waits_for_a_confident_track() -> None:
    # the tracker learns its velocity only from confident frames: below that it is stale
    unsure = TrackInput(TARGET, (60.0, 0.0), TrackState.TRACKING, 0.7, 0.0)
    assert _controller().update(unsure, now=0.0, hfov=30.0).motion == STOP
    lenient = _controller(feedforward_min_confidence=0.6)
    assert lenient.update(unsure, now=0.0, hfov=30.0).motion.pan > 0


def test_feedforward_goes_on_with_the_coasting_track_while_occluded() -> None:
    # hidden, the tracker coasts on the velocity it learned from its last confident frames:
    # the dome turns on with it, whatever the (low) confidence of the hidden target
    hidden = TrackInput(TARGET, (60.0, 0.0), TrackState.OCCLUDED, 0.2, 0.0)
    decision = _controller().update(hidden, now=0.0, hfov=30.0)
    assert decision.mode == "coast" and decision.motion.pan > 0
    assert decision.motion.zoom == Zoom.NONE  # still no zoom on a guess
    held = _controller(feedforward_while_occluded=False).update(hidden, now=0.0, hfov=30.0)
    assert held.motion == STOP  # in the stop band, no feed-forward: the seed's pure PID waits
    # an unsure but visible target is not coasting: the confidence gate still holds
    unsure = TrackInput(TARGET, (60.0, 0.0), TrackState.TRACKING, 0.2, 0.0)
    assert _controller().update(unsure, now=0.0, hfov=30.0).motion == STOP


def test_a_lost_track_is_followed_by_its_position_alone() -> None:
    # past the occlusion limit the box still coasts for follow_lost_s, and the dome follows
    # where it is (the PID, outside the stop band), not where it is heading: turning on
    # with the coast there sent walkers out of view (docs/daemon.md, "tenth pass")
    ctl = _controller(lost=LostConfig(follow_lost_s=1.0))
    centred = TrackInput(TARGET, (60.0, 0.0), TrackState.LOST, 0.3, 0.0)
    decision = ctl.update(centred, now=0.0, hfov=30.0)
    assert decision.mode == "coast" and decision.motion == STOP
    hidden = TrackInput(TARGET, (60.0, 0.0), TrackState.OCCLUDED, 0.3, 0.0)
    assert _controller().update(hidden, now=0.0, hfov=30.0).motion.pan > 0  # OCCLUDED does


def test_without_a_home_preset_going_home_zooms_fully_out_once() -> None:
    ctl = _controller(lost=LostConfig(hold_s=60.0, widen_s=5.0))
    assert ctl.go_home(10.0) is None  # no preset to send...
    widen = ctl.update(None, now=11.0, hfov=6.4)
    assert widen.mode == "widen" and widen.motion == Motion(zoom=Zoom.OUT)  # ...zoom out
    assert ctl.update(None, now=14.9, hfov=40.0).mode == "widen"
    assert ctl.update(None, now=15.1, hfov=60.0).motion == STOP  # for widen_s, then stop
    assert ctl.go_home(20.0) is None and ctl.update(None, now=21.0, hfov=60.0).motion == STOP
    # a lost selected target: stop, hold, then widen (once)
    lost = _controller(lost=LostConfig(follow_lost_s=0.0, hold_s=2.0, widen_s=5.0))
    modes = [lost.update(_track(TARGET, t, state=TrackState.LOST), now=t, hfov=10.0).mode
             for t in (0.0, 1.0, 2.5, 6.0, 8.0)]  # fmt: skip
    assert modes == ["lost", "lost", "widen", "widen", "lost"]
    # widen_s = 0: stay as is
    stay = _controller(lost=LostConfig(widen_s=0.0))
    assert stay.go_home(0.0) is None and stay.update(None, now=1.0, hfov=6.4).motion == STOP
