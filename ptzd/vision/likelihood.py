"""The observation model the particle filter weighs its particles with (pluggable).

Boxes here are centre-based: rows of `(cx, cy, w, h)` in frame pixels.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
Frame = NDArray[np.uint8]


class Likelihood(Protocol):
    """Scores candidate boxes against a target model learnt from the init box."""

    def init(self, frame: Frame, box: FloatArray) -> None:
        """Learn the target model from `box` (cx, cy, w, h) of `frame`."""
        ...

    def log_likelihood(self, frame: Frame, boxes: FloatArray) -> FloatArray:
        """log p(frame | box) up to a constant, one per row of `boxes` (N x 4)."""
        ...

    def part_similarities(self, frame: Frame, box: FloatArray) -> FloatArray:
        """Similarity in 0..1 of each part of the candidate at `box` (top to bottom; one
        value for a model with no parts) to the target model. Their mean is the occlusion
        test's similarity; their minimum says whether the whole candidate matches, not half
        of it (a re-identification)."""
        ...

    def adapt(self, frame: Frame, box: FloatArray) -> None:
        """Update the target model with the confidently tracked `box`."""
        ...

    def rescale(self, factor: float) -> None:
        """The image scale changed by `factor` (models tied to pixel sizes follow)."""
        ...
