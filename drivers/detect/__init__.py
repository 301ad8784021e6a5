"""Features from camera frames, host side (OpenCV + numpy): the pupil ellipse and the glints with their LEDs.

- `detector`: `detect_eye`, `detect_frame`, `Detection`, `FAILURES` (the method in its docstring);
- `ellipse`: robust ellipse fit of edge points; `glints`: glint candidates, centres, LED matching;
- `settings`: `DetectorSettings`, the tuning.
"""

from eyehil.drivers.detect.detector import FAILURES, Detection, detect_eye, detect_frame
from eyehil.drivers.detect.settings import DetectorSettings

__all__ = ["FAILURES", "Detection", "DetectorSettings", "detect_eye", "detect_frame"]
