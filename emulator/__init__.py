"""The simulated subject and device: anatomy, optics, fixation, forward model.

Knows nothing of hosts (see DESIGN.md). Frames of reference:

- head frame (mm): right-handed, origin midway between the unrotated anterior corneal apices,
  x to the subject's left, y up, z forward toward screen and camera;
- eye frame (mm): origin at that eye's unrotated anterior corneal apex, axes parallel to the head frame;
- image (px): OpenCV convention, origin at the top-left pixel centre, x right, y down.

Angles are degrees at every public interface, radians inside numerics only.
"""
