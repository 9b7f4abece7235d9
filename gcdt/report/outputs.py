"""`gcdt report`: a profile's tables, figures and report.md, from its run results alone."""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from gcdt.baselines.publish import AGENTS_DIR
from gcdt.experiments.profiles import Profile, deviations_text
from gcdt.paths import REPO_ROOT, outputs_root, results_dir, write_if_changed
from gcdt.report import agents, budget, fidelity, figures, generalisation, tables, targets
from gcdt.report.readme import grid_status_text, sections_text, wall_time_text

#: Table 1's TQC+HER cells from the published agents, beside them (`gcdt.report.agents`).
AGENTS_TABLE = "table1_tqc"


def write_tables(profile: Profile, runs) -> list[Path]:
    """Table 1 and the ablation (CSV, Markdown, LaTeX), Fig. 3-4's points and the two studies'
    tables into results/<profile>/, each where the profile has its runs; the paths written."""
    files: dict[str, str] = {}
    for name, table, caption in (
        ("table1", tables.table1(runs), "Performance comparison: Return / Success Rate (\\%)"),
        (
            "ablation",
            tables.ablation_table(runs),
            "Goal conditioning ablation: Return / Success Rate (\\%)",
        ),
    ):
        if not table.empty:
            files[f"{name}.csv"] = _csv(table)
            files[f"{name}.md"] = tables.to_markdown(table, paper=name == "table1") + "\n"
            files[f"{name}.tex"] = tables.to_latex(table, caption, f"tab:{name}")
    for name, (section, x) in tables.CURVES.items():  # Fig. 3 and Fig. 4's points
        curve = tables.curve_table(runs, section, x)
        if not curve.empty:
            files[f"{name}.csv"] = _csv(curve)
            files[f"{name}.md"] = tables.curve_markdown(curve, x) + "\n"
    study = targets.target_table(runs)
    if not study.empty:  # the return-target study
        best = targets.best_targets(runs)
        files["return_target.csv"], files["best_target.csv"] = _csv(study), _csv(best)
        files["best_target.md"] = targets.best_targets_markdown(best) + "\n"
    cells = fidelity.fidelity_table(runs)
    if not cells.empty:  # GC-DT against the paper's Table 1, beside its data
        files["fidelity.csv"] = _csv(cells)
        files["fidelity.md"] = fidelity.fidelity_markdown(cells) + "\n"
    checks = budget.budget_table(runs, profile.budget_factor)
    if not checks.empty:  # the fixed offline budget against a longer one
        files["budget_check.csv"] = _csv(checks)
        files["budget_check.md"] = budget.budget_markdown(checks) + "\n"
    regions = generalisation.generalisation_table(runs)
    if not regions.empty:  # the goal-generalisation study
        files["generalisation.csv"] = _csv(regions)
        files["generalisation.md"] = generalisation.generalisation_markdown(regions) + "\n"
    out = results_dir(profile.name)
    for name, text in files.items():
        write_if_changed(out / name, text)
    return [out / name for name in files]


def _csv(table: pd.DataFrame) -> str:
    return table.to_csv(index=False, float_format="%.4f")


def write_figures(profile: Profile, runs) -> list[Path]:
    """Fig. 2-4 and the learning curves, each drawn from the run results alone."""
    out = figures.figures_dir(profile.name)
    written = []
    for name, make in (
        ("fig2_architecture", figures.table1_architecture_figure),
        ("fig3_dataset_size", figures.dataset_size_figure),
        ("fig4_expert_ratio", figures.expert_ratio_figure),
        ("tqc_learning_curves", figures.tqc_learning_curves_figure),
        ("online_offline", figures.online_offline_figure),
        ("training_loss", figures.training_loss_figure),
        ("return_target", targets.target_figure),
        ("goal_generalisation", generalisation.generalisation_figure),
    ):
        fig = make(runs)
        if fig is not None:
            written += figures.save(fig, out, name)
    return written


def write_agents_table(agents_dir: str | Path = AGENTS_DIR) -> list[Path]:
    """Table 1's TQC+HER cells from the agents published in `agents_dir` (Markdown, CSV),
    written to results/experts/ under `outputs_root()`; the paths written."""
    out = outputs_root() / AGENTS_DIR.relative_to(REPO_ROOT)
    table = agents.agents_table(agents_dir)
    running = agents.in_progress_markdown(agents.in_progress_table(agents_dir))
    markdown = agents.agents_markdown(table) + (f"\n\n{running}" if running else "")
    files = {".md": markdown + "\n", ".csv": _csv(table)}
    for suffix, text in files.items():
        write_if_changed(out / f"{AGENTS_TABLE}{suffix}", text)
    return [out / f"{AGENTS_TABLE}{suffix}" for suffix in files]


def _fidelity_section(runs) -> str:
    cells = fidelity.fidelity_table(runs)
    if cells.empty:
        return ""
    return f"\n## {fidelity.CAPTION}\n\n{fidelity.fidelity_markdown(cells)}\n"


def write_report(profile: Profile) -> list[Path]:
    """Every table and results figure of `profile` from its run results, the published
    agents' table (`write_agents_table`), and report.md: the deviations from the paper,
    Table 1 and what the results cost (`wall_time_text`: record a reproduction before writing
    its report); the paths written."""
    runs = tables.load_runs(profile)
    written = write_tables(profile, runs) + write_figures(profile, runs) + write_agents_table()
    report = results_dir(profile.name) / "report.md"
    table1 = tables.to_markdown(tables.table1(runs))
    sections = sections_text(profile, runs)  # a grid still running: what is left, and its cost
    write_if_changed(
        report,
        f"# Results: profile `{profile.name}`\n\n"
        f"Generated by `gcdt report --profile {profile.name}` from "
        f"`results/{profile.name}/runs/` ({grid_status_text(profile, runs)}). "
        f"{wall_time_text(profile)}\n\n"
        + (f"{sections}\n\n" if sections else "")
        + f"{deviations_text(profile)}\n\n"
        "## Table 1: return / success rate (%), mean ± std over seeds [95 % bootstrap "
        "interval of the success rate over seeds]\n\n"
        f"{table1}\n" + _fidelity_section(runs),
    )
    return [*written, report]
