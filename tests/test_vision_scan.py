"""The learned trackers' local scan: the grid around the box and the two-frame rule."""

from __future__ import annotations

import numpy as np
import pytest

from ptzd.vision.scan import FoundTwice, grid_around, not_behind


def test_the_grid_around_a_box_by_hand() -> None:
    box = np.array([100.0, 50.0, 20.0, 40.0])
    grid = grid_around(box, radius=1.0, step=0.5, shape=(480, 640))
    # x: -1, -0.5, 0, 0.5, 1 widths; y: -0.5, 0, 0.5 heights
    assert grid.shape == (15, 4)
    assert sorted(set(grid[:, 0])) == [80.0, 90.0, 100.0, 110.0, 120.0]
    assert sorted(set(grid[:, 1])) == [30.0, 50.0, 70.0]
    assert np.all(grid[:, 2:] == [20.0, 40.0])


def test_the_grid_keeps_centres_in_the_frame() -> None:
    box = np.array([5.0, 10.0, 20.0, 40.0])
    grid = grid_around(box, radius=1.0, step=0.25, shape=(30, 40))
    assert grid.shape[0] > 0
    assert grid[:, 0].min() >= 0 and grid[:, 0].max() < 40
    assert grid[:, 1].min() >= 0 and grid[:, 1].max() < 30
    assert grid_around(np.array([-100.0, -100.0, 20.0, 40.0]), 1.0, 0.25, (30, 40)).shape == (0, 4)


def test_a_find_is_taken_only_when_found_again_within_half_a_box() -> None:
    finds = FoundTwice()
    a = np.array([100.0, 50.0, 20.0, 40.0])
    assert not finds.offer(a)  # the first time: a candidate
    assert finds.offer(a + np.array([9.0, 19.0, 0.0, 0.0]))  # within half a box: taken
    # 11 px across from the last find: a new candidate
    assert not finds.offer(a + np.array([20.0, 19.0, 0.0, 0.0]))
    assert not finds.offer(None)  # nothing found: the candidate is dropped
    assert not finds.offer(a)
    finds.clear()
    assert not finds.offer(a)


def test_the_candidate_moves_with_the_image() -> None:
    finds = FoundTwice()
    a = np.array([100.0, 50.0, 20.0, 40.0])
    finds.offer(a)
    shift = np.array([[1.0, 0.0, 30.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    finds.transform(shift)
    assert finds.candidate is not None
    assert finds.candidate[:2] == pytest.approx([130.0, 50.0])
    assert finds.offer(a + np.array([30.0, 0.0, 0.0, 0.0]))  # where the find is now: taken


def test_a_hidden_walker_may_be_ahead_of_where_he_went_in_or_beside_it_not_behind() -> None:
    # hidden at (100, 50), walking left (-x) at 2 px a frame; boxes 40 px wide: half a box
    # is 20 px, so centres at x <= 120 pass and x > 120 do not, whatever their y
    origin = np.array([100.0, 50.0, 40.0, 80.0])
    xs = [60.0, 100.0, 119.0, 120.0, 121.0, 180.0]
    boxes = np.array([[x, y, 40.0, 80.0] for x in xs for y in (20.0, 50.0, 90.0)])
    keep = not_behind(boxes, origin, np.array([-2.0, 0.0]), 40.0)
    assert keep.tolist() == [x <= 120.0 for x in xs for _ in range(3)]
    # walking down-right at 45 degrees: the distance is measured along the heading
    diagonal = np.array([[86.0, 36.0, 40.0, 80.0], [85.0, 35.0, 40.0, 80.0]])
    keep = not_behind(diagonal, origin, np.array([1.5, 1.5]), 40.0)
    assert keep.tolist() == [True, False]  # 19.8 and 21.2 px behind
    # under 0.02 box widths a frame (0.8 px here) there is no heading: all pass
    assert not_behind(boxes, origin, np.array([-0.7, 0.3]), 40.0).all()
