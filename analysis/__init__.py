"""Where the emulator and the host meet for science (imports both; nothing imports it).

- `study/`: the replication of Fischer, van der Merwe & Vandenheever 2023 (`eyehil study`);
- `discrepancy/`: find, name, add, show (`eyehil discrepancy`);
- `output_folder`: `staged_folder(out)`: a run's files appear in its output folder only once all are written.
"""
