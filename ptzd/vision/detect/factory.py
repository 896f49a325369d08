"""Build the configured detector."""

from __future__ import annotations

from pathlib import Path

from ptzd.errors import UsageError
from ptzd.vision.detect.bgcode import BackgroundCodebookDetector
from ptzd.vision.detect.codebook import Codebook, CodebookError
from ptzd.vision.detect.config import DetectorConfig
from ptzd.vision.detect.hog import DetectorUnavailableError, HogPeopleDetector, hog_available
from ptzd.vision.detect.types import Detection, Detector, Frame


class StillOrMovingDetector:
    """One detector while the camera is still, another (stateless) one while it moves."""

    def __init__(self, still: Detector, moving: Detector) -> None:
        self.still = still
        self.moving = moving
        self.name = f"{still.name}+{moving.name}"

    def reset(self) -> None:
        self.still.reset()
        self.moving.reset()

    def detect(self, frame: Frame, *, camera_moving: bool = False) -> list[Detection]:
        # the still detector is told about the move so it resets its background when it ends
        still = self.still.detect(frame, camera_moving=camera_moving)
        return self.moving.detect(frame, camera_moving=True) if camera_moving else still


def load_codebook(path: str) -> Codebook:
    return Codebook.load(Path(path)) if path else Codebook.load_default()


def make_detector(config: DetectorConfig) -> Detector:
    """The detector `config.kind` names, wrapped with HOG for moving views if asked.

    Raises `DetectorUnavailableError` when HOG is required but the OpenCV build lacks it,
    and `CodebookError` when the configured codebook cannot be read.
    """
    needs_hog = config.kind == "hog" or config.when_moving == "hog"
    if needs_hog and not hog_available():
        raise DetectorUnavailableError(
            "hog", "this OpenCV build has no HOGDescriptor (OpenCV 5 moved it to contrib)"
        )
    if config.kind == "hog":
        return HogPeopleDetector(config.hog)
    still = BackgroundCodebookDetector(config.bgcode, load_codebook(config.bgcode.codebook))
    if config.when_moving == "hog":
        return StillOrMovingDetector(still, HogPeopleDetector(config.hog))
    return still


def build_detector(config: DetectorConfig) -> Detector:
    """`make_detector` for a command line: a detector that cannot be built is a `UsageError`
    (one line naming the codebook file or the missing OpenCV module, exit 2)."""
    try:
        return make_detector(config)
    except (DetectorUnavailableError, CodebookError) as exc:
        raise UsageError(str(exc)) from None
