"""Host gaze estimation, pure numerics: what a host knows (`geometry`), the estimator interface
(`base`), the model-based estimator of Guestrin & Eizenman 2006 (`cornea`, `guestrin`) and the
interpolation mapping of Blignaut 2014 (`forms`, `blignaut`). Never imports the emulator."""
