"""Target detection: is the known target in this left image, where, and where in the room?

``make_detector(name, model, intrinsics)`` builds one of the registered detectors (``sift``,
``ncc``) for a :class:`TargetModel`; each reports its measured cost and its operating distance
range; :func:`locate_target` turns a detection plus the stereo disparity into a world position.
"""

from offboard.perception.detection.detector import Detection, Detector, detector_names, locate_target, make_detector
from offboard.perception.detection.target_model import TargetModel, TargetModelError

__all__ = ["Detection", "Detector", "TargetModel", "TargetModelError", "detector_names", "locate_target",
           "make_detector"]
