"""Wide sources: real video decoding (sequential, seeking, looping), ground-truth files."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from ptzd.errors import PtzdError, UsageError
from ptzd.sim.groundtruth import GroundTruth, GroundTruthError, load_ground_truth, save_ground_truth
from ptzd.sim.sources import (
    FrameIndexError,
    VideoFileSource,
    VideoSourceError,
    open_wide_source,
)

SIZE = (160, 120)
FRAMES = 60
VTEST = Path(__file__).resolve().parent.parent / "data" / "vtest.avi"


def _level(index: int) -> int:
    return (index * 4) % 256


def _write_levels(path: Path, fourcc: str) -> Path:
    """A real video: frame i is grey level 4*i with a contrasting bar at column 2*i."""
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*fourcc), 12.0, SIZE)
    assert writer.isOpened()
    for i in range(FRAMES):
        frame = np.full((SIZE[1], SIZE[0], 3), _level(i), np.uint8)
        frame[:, 2 * i : 2 * i + 8] = (_level(i) + 128) % 256
        writer.write(frame)
    writer.release()
    return path


@pytest.fixture(scope="module")
def video(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """MJPG: every frame a keyframe."""
    return _write_levels(tmp_path_factory.mktemp("video") / "levels.avi", "MJPG")


@pytest.fixture(scope="module")
def mp4_video(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """MPEG-4 part 2: predicted frames between keyframes, so seeking has to be exact."""
    return _write_levels(tmp_path_factory.mktemp("video") / "levels.mp4", "mp4v")


def _index_of(frame: np.ndarray) -> int:
    """Which frame this is, from its bar position (robust to JPEG loss)."""
    row = frame[SIZE[1] // 2, :, 1].astype(np.int16)
    level = int(np.median(frame[:, :, 1]))
    return int(np.argmax(np.abs(row - level) > 60)) // 2


def test_reads_real_encoded_video_in_order_without_seeking(video: Path) -> None:
    source = open_wide_source(str(video))
    assert (
        source.size == SIZE and source.fps == pytest.approx(12.0) and source.frame_count == FRAMES
    )
    assert source.ground_truth is None
    for i in range(FRAMES):
        frame = source.read(i)
        assert frame.shape == (SIZE[1], SIZE[0], 3) and frame.dtype == np.uint8
        assert _index_of(frame) == i
        assert abs(int(np.median(frame)) - _level(i)) <= 3
    assert isinstance(source, VideoFileSource) and source.seeks == 0


@pytest.mark.parametrize("kind", ["video", "mp4_video"])
def test_random_access_seeks_back_and_skips_ahead(
    kind: str, request: pytest.FixtureRequest
) -> None:
    source = VideoFileSource(str(request.getfixturevalue(kind))).open()
    assert source.frame_count == FRAMES
    for i in (40, 5, 6, 30, 59, 0, 12, 55, 21):
        assert _index_of(source.read(i)) == i
    assert source.seeks >= 3  # 40 -> 5, 59 -> 0 and 55 -> 21 go backwards


def test_same_frame_twice_is_a_fresh_array(video: Path) -> None:
    source = VideoFileSource(str(video)).open()
    first = source.read(3)
    first[:] = 0
    assert _index_of(source.read(3)) == 3


def test_looped_video_wraps_and_played_once_ends(video: Path) -> None:
    looped = open_wide_source(str(video), loop=True)
    assert _index_of(looped.read(FRAMES + 7)) == 7
    assert _index_of(looped.read(3 * FRAMES + 1)) == 1
    once = open_wide_source(str(video))
    with pytest.raises(FrameIndexError) as err:
        once.read(FRAMES)
    assert err.value.index == FRAMES and err.value.frame_count == FRAMES


def test_unreadable_or_missing_video_is_a_clear_error(tmp_path: Path) -> None:
    junk = tmp_path / "junk.avi"
    junk.write_bytes(np.random.default_rng(0).integers(0, 256, 20000, dtype=np.uint8).tobytes())
    with pytest.raises(VideoSourceError) as err:
        open_wide_source(str(junk))
    assert str(junk) in str(err.value) and isinstance(err.value, UsageError)
    with pytest.raises(VideoSourceError, match="no such file"):
        open_wide_source(str(tmp_path / "missing.mp4"))


def test_ground_truth_round_trips_and_is_checked_against_the_video(
    video: Path, tmp_path: Path
) -> None:
    gt = GroundTruth(
        SIZE,
        12.0,
        {3: {0: (1.0, 2.0, 30.0, 60.0), 10: (4.5, 2.0, 30.0, 61.0)}, 7: {}},
        {3: {0: 1.0, 10: 0.25}},
    )
    path = tmp_path / "gt.json"
    save_ground_truth(gt, path)
    doc = json.loads(path.read_text())
    # exactly the shared format (plus the optional visibility map)
    assert doc["size"] == [160, 120] and doc["fps"] == 12.0
    assert doc["tracks"][0]["id"] == 3 and doc["tracks"][0]["frames"]["10"] == [4.5, 2, 30, 61]
    assert load_ground_truth(path) == gt
    source = open_wide_source(str(video), gt_path=str(path))
    assert source.ground_truth == gt

    wrong = tmp_path / "wrong.json"
    save_ground_truth(GroundTruth((768, 576), 10.0, {}), wrong)
    with pytest.raises(GroundTruthError, match=r"768x576.*160x120"):
        open_wide_source(str(video), gt_path=str(wrong))


@pytest.mark.parametrize(
    ("text", "where"),
    [
        ("not json", "not JSON"),
        ("[]", "expected a JSON object"),
        ('{"size": [1, 2], "fps": 1}', "missing key 'tracks'"),
        ('{"size": [0, 2], "fps": 1, "tracks": []}', "at size"),
        ('{"size": [4, 2], "fps": -1, "tracks": []}', "at fps"),
        ('{"size": [4, 2], "fps": 1, "tracks": [{"id": 1}]}', r"at tracks\[0\]"),
        (
            '{"size": [4, 2], "fps": 1, "tracks": [{"id": 1, "frames": {"x": [0,0,1,1]}}]}',
            "frame index",
        ),
        (
            '{"size": [4, 2], "fps": 1, "tracks": [{"id": 1, "frames": {"2": [0,0,1]}}]}',
            r'frames\["2"\]',
        ),
        (
            '{"size": [4, 2], "fps": 1, "tracks": [{"id": 1, "frames": {}}, {"id": 1, "frames": {}}]}',  # noqa: E501
            "duplicate track id 1",
        ),
    ],
)
def test_malformed_ground_truth_names_the_problem(tmp_path: Path, text: str, where: str) -> None:
    path = tmp_path / "gt.json"
    path.write_text(text)
    with pytest.raises(GroundTruthError, match=where) as err:
        load_ground_truth(path)
    assert isinstance(err.value, PtzdError) and str(path) in str(err.value)


def test_synthetic_specs() -> None:
    source = open_wide_source("synthetic:5")
    assert source.size == (1280, 720) and source.fps == 25.0 and source.frame_count == 1500
    assert source.read(0).shape == (720, 1280, 3)
    default = open_wide_source("synthetic", loop=True)
    assert np.array_equal(default.read(1500), open_wide_source("synthetic:0").read(0))
    with pytest.raises(UsageError, match="integer seed"):
        open_wide_source("synthetic:abc")


@pytest.mark.skipif(not VTEST.is_file(), reason="run ./scripts/fetch-vtest.sh for data/vtest.avi")
def test_vtest_avi() -> None:
    source = open_wide_source(str(VTEST), loop=True)
    assert (
        source.size == (768, 576)
        and source.fps == pytest.approx(10.0)
        and source.frame_count == 795
    )
    wanted = (700, 3, 411, 410, 100, 794, 0)
    in_order = {}
    for i in range(795):
        frame = source.read(i)
        if i in wanted:
            in_order[i] = frame
    assert in_order[794].shape == (576, 768, 3)
    assert np.array_equal(source.read(795), in_order[0])
    jumping = open_wide_source(str(VTEST))
    for i in wanted:  # seeks land on exactly the frame decoded in order
        assert np.array_equal(jumping.read(i), in_order[i])
