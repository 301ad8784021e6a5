"""The discrepancy workflow: find where simulation and measured data disagree, name the missing effect, add it,
show the gap shrink (docs/discrepancy.md).

- `workflow`: `run_discrepancy`, `hidden_measured` (the rounds of find, name, add; then show);
- `data`: measured data (per-condition errors of real subjects); `metrics`: the experiments compared;
- `guestrin`: the Guestrin 2006 experiment batched over eyes; `stats`: per-condition tests and the gap measure;
- `search`: fitting an effect's parameters; `report`: the output folder; `cli`: `eyehil discrepancy`.
"""
