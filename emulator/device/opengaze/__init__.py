"""The Gazepoint Open Gaze API facade: the virtual tracker as a GP3 on TCP port 4242 (docs/opengaze.md).

- `server`: `OpenGazeServer` (sockets, limits, the one thread) and `server_for` (`eyehil emulate --link opengaze`);
- `core`: `OpenGazeDevice`, records in, records out (GET/SET answers, REC data, CAL calibration), no I/O;
- `calibration`: the calibration the tracker paces, fitted with the gazers of `zmq_calibration`;
- `samples`: the data values of exposures (gaze, pupils, eye positions), vectorised, with their units;
- `filters`: the fixation (FPOG) and blink (BK) filters.

The record codec is `eyehil.protocols.opengaze`.
"""
