"""Person detection: the seed-002 background + codebook detector and OpenCV's HOG.

Import the pieces from their modules (`ptzd.vision.detect.factory.make_detector`, ...):
this package's `__init__` stays free of numpy/cv2 so loading the config stays fast.
"""
