"""Host gaze estimation, pure numerics. Never imports the emulator.

Modules: `geometry` (what a host knows: camera, LEDs, screen), `base` (the estimator interface and
error forms), `cornea` (corneal and pupil centres from features), `guestrin` (the model-based estimator
of Guestrin & Eizenman 2006, its named options `GuestrinOptions` and profiles `PROFILES`: "best" and
"study-code"), `guestrin_batch` (the same calibration for many eyes at once), `forms` and `blignaut`
(the interpolation mapping of Blignaut 2014, with `fit_form_many` for batched fits).

Batched API (the study and the discrepancy workflow share it; one implementation):

    from eyehil.drivers.gaze.guestrin_batch import calibrate_many
    fit = calibrate_many(geometry, samples, targets_mm, options="best")   # or "study-code", or GuestrinOptions
    fit.params          # (N, 4) R mm, K mm, alpha deg, beta deg; NaN rows for eyes that could not calibrate
    fit.reasons         # {eye index: why} for those eyes
    fit.estimate(s)     # (N, ..., 2) screen mm for samples s (N, ...) of the same eyes (any extra axes)
    fit.errors_deg(s, targets)  # (N, ...) deg in the options' error metric

`samples` is an `EyeSamples` of batch shape (N eyes, T calibration targets) (pupil (N, T, 2) px, glints
(N, T, n_leds >= 2, 2) px, valid (N, T)); targets (T, 2) or (N, T, 2) screen mm; `start=` (N, 4) warm-
starts the fit (e.g. from a previous parameter set). Results equal the per-eye `GuestrinEstimator` to 1e-6
deg in the mean errors (tests/test_gaze_batch.py). Blignaut: `blignaut.fit_form_many(form, features (N,
n, 2), values (N, n), used (N, n))` -> coefficients (N, terms) and per-fit failure reasons.
"""
