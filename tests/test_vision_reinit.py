"""`Tracker.init` starts over: the daemon keeps one tracker per camera and re-initialises it
on each new target (so its buffers are allocated once, not per lock), which is only right if
a re-initialised tracker behaves exactly like a new one."""

from __future__ import annotations

import numpy as np
import pytest

from ptzd.vision.config import TrackerConfig
from ptzd.vision.tracking import Tracker, TrackResult, make_tracker
from tests.vision_helpers import Scene


def _follow(tracker: Tracker, scene: Scene, frames: int) -> list[TrackResult]:
    tracker.init(scene.frame(0), scene.truth(0))
    return [tracker.update(scene.frame(t)) for t in range(1, frames)]


@pytest.mark.parametrize("kind", ["color", "rf", "svm"])
def test_a_reinitialised_tracker_behaves_like_a_new_one(kind: str) -> None:
    config = TrackerConfig(kind=kind, seed=5)
    target = Scene(
        seed=1, start=(60.0, 80.0, 24.0, 60.0), velocity=(2.0, 0.5), occluder_x=(120, 135)
    )
    fresh = _follow(make_tracker(config), target, 40)

    used = make_tracker(config)
    # an earlier target: another size and place, panned by the camera, zoomed, then occluded
    earlier = Scene(seed=2, start=(200.0, 40.0, 40.0, 90.0), velocity=(-1.5, 0.3),
                    occluder_x=(150, 230))  # fmt: skip
    used.init(earlier.frame(0), earlier.truth(0))
    for t in range(1, 20):
        used.update(earlier.frame(t), ego_motion=np.array([1.0, 0.0]) if t < 5 else None)
        if t == 8:
            used.rescale(1.25, (160.0, 120.0))
    again = _follow(used, target, 40)

    assert [r.state for r in again] == [r.state for r in fresh]
    np.testing.assert_array_equal([r.box for r in again], [r.box for r in fresh])
    np.testing.assert_array_equal([r.confidence for r in again], [r.confidence for r in fresh])
