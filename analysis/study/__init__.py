"""The replication of Fischer, van der Merwe & Vandenheever 2023: both experiments on 100 eyes, the statistics,
the findings with verdicts, the report and its figures.

- `replication`: `run_study`, `analyse`; `experiments`: the two experiments per eye (pure);
- `bridge`: what a host knows of a scene (tracker geometry, targets);
- `stats`: the statistics; `summary`: a run's published statistics; `findings`: each finding with a verdict;
- `breakdown`: which added anatomy moves the errors (`--anatomy full`: each addition alone, variance shares);
- `published`: the published figures (`data/published_results.json`); `report`, `figures`: the output folder;
- `cli`: `eyehil study`.
"""
