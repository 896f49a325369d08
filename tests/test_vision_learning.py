"""`LearningGate`: which tracked boxes the learned trackers may learn from."""

from __future__ import annotations

import cv2
import numpy as np

from ptzd.vision.color import ColourVote
from ptzd.vision.config import TrackerConfig
from ptzd.vision.learning import LearningGate
from ptzd.vision.likelihood import FloatArray, Frame
from ptzd.vision.tracking import centre_box
from tests.vision_helpers import Scene


def _vote(frame: Frame, box: FloatArray) -> ColourVote:
    config = TrackerConfig()
    vote = ColourVote(config.color, config.gmm, 1.0)
    vote.init(frame, box)
    return vote


def _walker() -> tuple[Frame, FloatArray, ColourVote]:
    """The scene's first frame, the walker's box (centre form) and a colour vote on him."""
    scene = Scene()
    frame = scene.frame(0)
    box = centre_box(scene.truth(0))
    return frame, box, _vote(frame, box)


def test_a_box_in_which_nothing_moved_is_not_learned_while_the_camera_is_still() -> None:
    frame, box, vote = _walker()
    gate = LearningGate(True, False, 0.02, 0.6)
    assert gate.allows(frame, box, 0.3, True, vote)
    assert not gate.allows(frame, box, 0.01, True, vote)
    assert gate.allows(frame, box, 0.01, False, vote)  # the camera turned: motion unreliable
    assert gate.allows(frame, box, None, True, vote)  # motion not known yet
    assert LearningGate(False, False, 0.02, 0.6).allows(frame, box, 0.0, True, vote)


def test_a_box_the_colour_model_calls_occluded_is_not_learned() -> None:
    frame, box, vote = _walker()
    x, y, w, h = box[0] - box[2] / 2, box[1] - box[3] / 2, box[2], box[3]
    gate = LearningGate(False, True, 0.02, 0.6)
    assert gate.allows(frame, box, None, True, vote)
    hidden = frame.copy()
    cv2.rectangle(hidden, (round(x) - 5, round(y) - 5), (round(x + w) + 5, round(y + h) + 5),
                  (200, 60, 30), -1)  # fmt: skip
    assert not gate.allows(hidden, box, None, True, vote)
    assert LearningGate(False, False, 0.02, 0.6).allows(hidden, box, None, True, vote)
    # on grey frames the colour vote is off, and so is this test
    grey = np.asarray(cv2.cvtColor(hidden, cv2.COLOR_BGR2GRAY), np.uint8)
    grey_vote = _vote(np.asarray(cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY), np.uint8), box)
    assert gate.allows(grey, box, None, True, grey_vote)
