"""Optics of the eye and the camera, vectorised numpy over batches of rays (mm, eye-local or head frame as
each module states).

- `conic`: conic surfaces of revolution and ray intersection; `biconic`: toric (biconic) surfaces, tilted and
  decentred;
- `rays`: refraction and reflection (vector forms); `newton`: a batched two-unknown Newton iteration;
- `glint`: the corneal reflection of an LED into the camera; `pupil`: the apparent pupil through the cornea;
  `fused`: the pupil solve's ray trace through conic corneas, component-wise (the hot loop);
- `camera`: the pinhole camera (head frame mm -> image px, OpenCV convention); `ellipse`: batched ellipse fit.
"""
