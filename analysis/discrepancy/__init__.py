"""The discrepancy workflow: find where simulation and measured data disagree, name the missing effect, add it,
show the gap shrink (docs/discrepancy.md).

- `workflow`: `run_discrepancy`, `hidden_measured` (the rounds of find, name, add; then show);
- `rounds`: one round's find, name and add, and the outcome's criterion; `refit`: the added effects refitted
  together, and other effects tried in their places;
- `data`: measured data (per-condition errors of real subjects); `metrics`: the experiments compared;
- `recording`: eyehil recordings as measured subjects (features per target and head position);
- `measured`: measured data from a built-in set, a file or a folder of recordings (`--measured`);
- `guestrin`: the Guestrin 2006 experiment batched over eyes; `stats`: per-condition tests and the gap measure;
- `search`: fitting an effect's parameters; `profile`: a later round's candidates scored with the earlier
  effects' parameters free; `report`: the output folder; `cli`: `eyehil discrepancy`;
- `trials`: blind trials at random strengths and their rates (``python -m eyehil.analysis.discrepancy.trials``).
"""
