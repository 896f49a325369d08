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
