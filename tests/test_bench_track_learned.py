"""bench/track_learned.py's tracker seeds: each sequence's scores averaged over them."""

from __future__ import annotations

import pytest

from bench.track_learned import mean_over_seeds


def _run(auc: float, lost: int, fps: float, success: list[float]) -> dict[str, object]:
    return {"frames": 10, "lost_frames": lost, "auc": auc, "precision_20": auc / 2,
            "mean_iou": auc, "success": success, "fps": fps}  # fmt: skip


def test_scores_are_averaged_over_seeds_and_fps_is_the_median() -> None:
    runs = [_run(0.2, 1, 100.0, [1.0, 0.2]), _run(0.6, 2, 300.0, [1.0, 0.6]),
            _run(0.7, 6, 200.0, [0.5, 0.7])]  # fmt: skip
    out = mean_over_seeds(runs)
    assert out["auc"] == pytest.approx(0.5)
    assert out["precision_20"] == pytest.approx(0.25)
    assert out["success"] == pytest.approx([2.5 / 3, 0.5])
    assert out["lost_frames"] == 3  # the mean, rounded: print_table wants an int
    assert out["fps"] == 200.0
    assert out["auc_per_seed"] == [0.2, 0.6, 0.7]
    assert out["frames"] == 10


def test_one_seed_is_the_run_itself() -> None:
    run = _run(0.3, 0, 50.0, [1.0])
    assert mean_over_seeds([run]) is run


def _walker(shares: list[float], box: tuple[float, float, float, float] = (100, 100, 20, 50)):
    frames = range(len(shares))
    return dict.fromkeys(frames, box), dict(zip(frames, shares, strict=True))


def test_occlusion_windows_are_where_a_walker_is_hidden_and_comes_back() -> None:
    from types import SimpleNamespace

    from bench.track_learned import pick_occlusions

    walkers = {
        1: _walker([1.0] * 20 + [0.2] * 12 + [0.9] * 20),  # hidden 12 frames, then back
        2: _walker([1.0] * 20 + [0.3] * 30 + [0.9] * 5),  # hidden, back for too short
        3: _walker([1.0] * 60),  # never hidden
        4: _walker([1.0] * 10 + [0.0] * 40 + [1.0] * 10),  # hidden most of the window
        5: _walker([0.9] * 10 + [0.4] * 20 + [1.0] * 30),  # the most hidden that qualifies
        6: _walker([1.0] * 20 + [0.2] * 12 + [0.9] * 20, box=(0, 100, 20, 50)),  # on the border
    }
    gt = SimpleNamespace(
        size=(640, 480),
        tracks={tid: boxes for tid, (boxes, _) in walkers.items()},
        visibility={tid: shares for tid, (_, shares) in walkers.items()},
    )
    assert pick_occlusions(gt, max_frames=100, count=5) == [(20, 5, 0, 59), (12, 1, 0, 51)]
    assert pick_occlusions(gt, max_frames=100, count=1) == [(20, 5, 0, 59)]
    # a window too short to see him come back does not qualify
    assert pick_occlusions(gt, max_frames=25, count=5) == []


def test_override_is_laid_over_the_tracker_table() -> None:
    from pydantic import ValidationError

    from bench.track_learned import ConfigTracker, make

    rf = make("rf", 3, {"rf": {"colour_weight": 0.0}})
    assert isinstance(rf, ConfigTracker)
    assert (rf.config.kind, rf.config.seed, rf.config.rf.colour_weight) == ("rf", 3, 0.0)
    assert rf.config.rf.coast  # the rest of the table as shipped
    static = make("rf-static", 0, {"rf": {"coast": False}})
    assert isinstance(static, ConfigTracker)
    assert not static.config.rf.online and not static.config.rf.coast
    assert make("color", 1).config.kind == "color"  # type: ignore[attr-defined]
    with pytest.raises(ValidationError, match="colour_wieght"):
        make("svm", 0, {"svm": {"colour_wieght": 1.0}})


def test_a_peer_that_cannot_start_scores_every_frame_lost() -> None:
    import cv2
    import numpy as np

    from bench.track import OpenCVTracker, Sequence, run_tracker

    started: list[tuple[int, int, int, int]] = []

    class CannotStart:  # as CSRT on a walker's first pixels at the frame's edge
        def init(self, frame: object, rect: tuple[int, int, int, int]) -> None:
            started.append(rect)
            raise cv2.error("copyMakeBorder: !_src.empty()")

    frames = [np.zeros((48, 64, 3), np.uint8) for _ in range(4)]
    for box in ((0.0, 20.0, 6.0, 8.0), (0.0, 20.0, 1.0, 1.0)):
        truth = dict.fromkeys(range(4), box)
        peer = OpenCVTracker("csrt", CannotStart)
        run = run_tracker(peer, Sequence("edge", "x", frames, truth))
        assert run.score.frames == 3 and run.score.lost_frames == 3 and run.score.auc == 0.0
    # the 1 x 1 box is never handed to the peer (MIL never returns on one)
    assert started == [(0, 20, 6, 8)]


def test_scaled_sequence_is_what_a_camera_of_that_resolution_sees() -> None:
    import numpy as np

    from bench.track import Sequence, scaled

    frame = np.zeros((48, 64, 3), np.uint8)
    frame[20:36, 10:18] = 255  # a person at (10, 20, 8, 16)
    shift = np.array([[1.0, 0.0, 3.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    seq = Sequence("s", "c", [frame, frame], {0: (10, 20, 8, 16)}, {1: shift}, "frames 0..1")
    big = scaled(seq, 2.0)
    assert big.frames[0].shape == (96, 128, 3) and big.frames[0].dtype == np.uint8
    ys, xs = np.nonzero(big.frames[0][:, :, 0] > 127)
    assert (xs.min(), ys.min(), xs.max() + 1, ys.max() + 1) == (20, 40, 36, 72)
    assert big.truth[0] == pytest.approx((20, 40, 16, 32))
    # the camera's motion in pixels doubles too: 3 px -> 6 px
    np.testing.assert_allclose(big.ego[1] @ [50.0, 7.0, 1.0], [56.0, 7.0, 1.0])
    assert big.note == "frames 0..1, x2"
    small = scaled(seq, 0.5)
    assert small.frames[1].shape == (24, 32, 3)
    assert small.truth[0] == pytest.approx((5, 10, 4, 8))
    assert scaled(seq, 1.0) is seq
    with pytest.raises(ValueError, match="positive"):
        scaled(seq, 0.0)


@pytest.mark.parametrize(
    ("option", "value", "message"),
    [
        *[
            ("--frame-scale", v, "--frame-scale must be within 0.05..8")
            for v in ("0", "-1", "9", "nan")
        ],
        *[("--dusk", v, "--dusk must be within 0..1") for v in ("-0.1", "1.5", "nan")],
    ],
)
def test_an_option_out_of_range_is_refused_before_anything_runs(
    option: str, value: str, message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    from bench.track_learned import main

    with pytest.raises(SystemExit) as exc:
        main([option, value, "--classes", "vtest", "--no-speed"])
    assert exc.value.code == 2
    assert message in capsys.readouterr().err


def test_greyed_sequence_is_single_channel_with_the_same_truth() -> None:
    import numpy as np

    from bench.track import Sequence, greyed

    frame = np.zeros((48, 64, 3), np.uint8)
    frame[20:36, 10:18] = (0, 0, 255)  # red in BGR
    seq = Sequence("s", "c", [frame, frame[:, :, 0].copy()], {0: (10, 20, 8, 16)}, {}, "x2")
    grey = greyed(seq)
    assert [f.shape for f in grey.frames] == [(48, 64), (48, 64)]
    assert grey.frames[0].dtype == np.uint8
    assert grey.frames[0][25, 12] == 76  # ITU-R BT.601 luma of pure red: 0.299 * 255
    assert grey.frames[1] is seq.frames[1]  # already single-channel
    assert grey.truth == seq.truth and grey.note == "x2, grey"


def test_dusk_turns_the_frames_grey_from_its_point_on() -> None:
    import numpy as np

    from bench.track import Sequence, dusk

    red = np.zeros((8, 8, 3), np.uint8)
    red[..., 2] = 255
    seq = Sequence("s", "c", [red] * 4, {0: (1, 1, 4, 4)}, {}, "")
    evening = dusk(seq, 0.5)
    assert [f.shape for f in evening.frames] == [(8, 8, 3)] * 4
    assert evening.frames[1] is red
    # from frame 2 on: BT.601 luma of pure red (76) in all three channels
    assert all(np.all(f == 76) for f in evening.frames[2:])
    assert evening.truth == seq.truth and evening.note == "grey from 2"
    assert all(np.all(f == 76) for f in dusk(seq, 0.0).frames)
    with pytest.raises(ValueError, match=r"within 0\.\.1"):
        dusk(seq, 1.5)
