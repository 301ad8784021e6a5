"""Synthetic infrared frames: the ray-traced geometry of each exposure drawn as 8-bit camera images.

- `renderer`: `render_roi`, `render_full`, `RenderSettings`, `Truth` (the model and its noise in its docstring);
- `geometry`: image-plane outlines of pupil, limbus, glints and eyelids (pure, batched numpy);
- `draw`: anti-aliased drawing of one eye into a radiance canvas;
- `noise`: counter-based sensor noise (SplitMix64 by pixel, keyed by seed, frame id and eye: the device's images);
- `kernels`: the sensor's noise over a canvas compiled (`kernels.c`, built on first use), equal to the numpy path;
- `cli`: `eyehil render` (example frames with their ground truth).
"""
