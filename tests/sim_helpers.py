"""Test helpers for the simulator: a wide source made of numpy frames."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ptzd.sim.groundtruth import GroundTruth


@dataclass
class ArraySource:
    """A wide source made of numpy frames (a real `WideSource`, just not decoded from a file)."""

    frames: list[np.ndarray]
    fps: float = 10.0
    ground_truth: GroundTruth | None = None

    @property
    def size(self) -> tuple[int, int]:
        return self.frames[0].shape[1], self.frames[0].shape[0]

    @property
    def frame_count(self) -> int:
        return len(self.frames)

    def read(self, index: int) -> np.ndarray:
        return self.frames[index % len(self.frames)].copy()
