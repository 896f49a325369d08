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

    def similarity(self, frame: Frame, box: FloatArray) -> float:
        """Similarity in 0..1 of the candidate at `box` to the target model (occlusion test)."""
        ...

    def adapt(self, frame: Frame, box: FloatArray) -> None:
        """Update the target model with the confidently tracked `box`."""
        ...

    def rescale(self, factor: float) -> None:
        """The image scale changed by `factor` (models tied to pixel sizes follow)."""
        ...
