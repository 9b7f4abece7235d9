"""Tables and figures of the paper from `results/<profile>/` alone: `gcdt report`.

One module per purpose:

- `gcdt.report.outputs`: `write_report(profile)` writes Table 1 and the ablation (CSV,
  Markdown, LaTeX), the points of Fig. 3 and Fig. 4 and the studies' tables into
  results/<profile>/, Fig. 2-4, the learning curves and the studies' figures (PNG, PDF) into
  figures/<profile>/, and results/<profile>/report.md with the profile's deviations from the
  paper and the wall time its reproduce.json records; both folders lie under
  `gcdt.paths.outputs_root()` (the repository, or a reproduction's own).
  `write_agents_table()` (part of `write_report`) writes results/experts/table1_tqc.{md,csv}
  there from the published TQC+HER agents.
- `gcdt.report.tables`, `figures`, `targets` (the return-target study) and `generalisation`
  (the goal-generalisation study), `budget` (a fixed offline budget against a longer one): what
  those files hold, computed from the run results;
  `agents`: Table 1's TQC+HER cells from the published agents.
- `gcdt.report.readme`: the README's results section (`gcdt report --readme`) and
  results/<profile>/reproduce.json, the wall time `make reproduce` measured.
- `gcdt.report.reproduction`: a reproduction checked against the published results, and
  publishing.
- `gcdt.report.notebook`: the notebooks' helpers (`check_parameters`, `show`, `run_grid`).

The names below are importable from `gcdt.report` itself.
"""

from __future__ import annotations

from gcdt.report import agents, budget, figures, generalisation, tables, targets
from gcdt.report.notebook import (
    check_parameters,
    notebook_figures_dir,
    outputs_note,
    renders_published,
    run_grid,
    show,
)
from gcdt.report.outputs import write_agents_table, write_figures, write_report, write_tables
from gcdt.report.readme import readme_block, record_reproduction, update_readme, wall_time_text

__all__ = [
    "agents",
    "budget",
    "check_parameters",
    "figures",
    "generalisation",
    "notebook_figures_dir",
    "outputs_note",
    "readme_block",
    "record_reproduction",
    "renders_published",
    "run_grid",
    "show",
    "tables",
    "targets",
    "update_readme",
    "wall_time_text",
    "write_agents_table",
    "write_figures",
    "write_report",
    "write_tables",
]
