"""Which tracked boxes a learned tracker (`rf`, `svm`) may learn from (beyond the seeds).

Both trackers learn their target from the boxes they track: rf every tracked frame while
its memory fills (Ko's sec. 4.3) and on learning-grade frames after, svm every confident
box. A walker who goes behind a column or is passed by a van in those frames teaches them
the column or the van, which they then score as the target. Two tests keep such boxes out:

- motion (`learn_needs_motion`): something moved in the box, the camera being still (while
  it turns, the commanded image motion is a little off and the background "moves"). A
  hidden target's box shows the still occluder; a standing target is left as learned.
- colour (`learn_needs_colour`, colour frames only): the colour tracker's model (the
  learned tracker's `ColourVote`) scores the box at its occlusion threshold or above.
"""

from __future__ import annotations

from dataclasses import dataclass

from ptzd.vision.color import ColourVote
from ptzd.vision.likelihood import FloatArray, Frame


@dataclass(frozen=True)
class LearningGate:
    needs_motion: bool
    needs_colour: bool
    min_moving_fraction: float  # `tracker.stillness.min_moving_fraction`
    colour_threshold: float  # `tracker.occlusion.similarity_threshold`

    def allows(
        self,
        frame: Frame,
        box: FloatArray,
        moved: float | None,
        camera_still: bool,
        colour: ColourVote,
    ) -> bool:
        """Whether `box` (centre form) of `frame` may be learned; `moved` is its moving
        share this frame (None: not known, e.g. the first frame)."""
        if (
            self.needs_motion
            and camera_still
            and moved is not None
            and moved < self.min_moving_fraction
        ):
            return False
        return not self.needs_colour or colour.agrees(frame, box, self.colour_threshold)
