"""The simulated subject and device: anatomy, optics, fixation, forward model, frames, the virtual device.

- `eye/`: anatomy (EyeModel, the Rozema 2011 population, published and normative eyes, media);
- `optics/`: conics, refraction/reflection, glint and apparent-pupil solvers, camera, ellipse fit;
- `scene/`: camera, LEDs, screen, targets, head positions, presets; `fixation`: Listing's-law fixations;
- `forward`: (eyes, scene, targets) -> `features.Features`, batched; `feature_file`: features on disk, written
  chunk by chunk; `simulate`: `eyehil simulate` (chunks on a process pool or Dask, streamed to a file);
- `effects/`: named model extensions (the discrepancy workflow's vocabulary); `render/`: synthetic frames;
- `device/`: the virtual tracker and its links and facades; `data/`: the figures the physics needs.

Knows nothing of hosts (see DESIGN.md). Frames of reference:

- head frame (mm): right-handed, origin midway between the unrotated anterior corneal apices,
  x to the subject's left, y up, z forward toward screen and camera;
- eye frame (mm): origin at that eye's unrotated anterior corneal apex, axes parallel to the head frame;
- image (px): OpenCV convention, origin at the top-left pixel centre, x right, y down.

Angles are degrees at every public interface, radians inside numerics only.
"""
