"""Tables and figures of the paper from `results/<profile>/` alone: `gcdt report`.

write_report(profile) writes Table 1 and the ablation table (CSV, Markdown, LaTeX) and, where
the profile makes them, the points of Fig. 3 and Fig. 4 (CSV, Markdown), the return-target and
goal-generalisation studies (`gcdt.report.targets`, `gcdt.report.generalisation`) into
results/<profile>/, Fig. 2-4, the learning curves and the studies' figures (PNG, PDF) into
figures/<profile>/, and results/<profile>/report.md, which also lists the profile's deviations
from the paper; both folders lie under `gcdt.paths.outputs_root()` (the repository, or a
reproduction's own). `make reproduce` adds results/<profile>/reproduce.json: its measured wall
time. The notebooks' helpers (`show`, `run_grid`) are here too.
"""

from __future__ import annotations

import datetime as dt
import json
from pathlib import Path

from gcdt.errors import GcdtError
from gcdt.experiments.profiles import PROFILES, Profile, deviations_text
from gcdt.paths import (
    OUTPUTS_ENV,
    REPO_ROOT,
    artifacts_dir,
    is_published,
    outputs_root,
    results_dir,
    write_between_markers,
    write_if_changed,
    write_json_atomic,
)
from gcdt.report import figures, generalisation, tables, targets

README_START, README_END = "<!-- results:start -->", "<!-- results:end -->"


def check_parameters(profile: object, backend: object) -> Profile:
    """Validate notebook parameters (papermill may inject anything); return the profile."""
    from gcdt.experiments.sweep import BACKENDS

    if not isinstance(profile, str) or profile not in PROFILES:
        raise GcdtError(
            f"parameter profile must be one of {', '.join(PROFILES)} (a string), got {profile!r}"
        )
    if not isinstance(backend, str) or backend not in BACKENDS:
        raise GcdtError(
            f"parameter backend must be one of {', '.join(BACKENDS)} (a string), got {backend!r}"
        )
    return PROFILES[profile]


def renders_published(profile: Profile) -> bool:
    """Whether a notebook reads the repository's published results of `profile` (JupyterLab
    without `$GCDT_OUTPUTS`): it then renders them and never runs or rewrites anything there;
    `make reproduce` is what re-runs. The smoke profile publishes nothing, so it always runs."""
    return is_published() and profile.name != "smoke"


def outputs_note(profile: Profile) -> str:
    """Which results a notebook reads and writes: the published ones, or a reproduction's."""
    where = results_dir(profile.name)
    shown = where.relative_to(REPO_ROOT) if where.is_relative_to(REPO_ROOT) else where
    if renders_published(profile):
        return (
            f"Results: {shown}/ (the repository's published results, rendered as they are; "
            f"figures drawn here go to {notebook_figures_dir(profile)})"
        )
    if is_published():
        return f"Results: {shown}/ (this checkout's own {profile.name} runs)"
    return f"Results: {shown}/ (this reproduction's own folder, ${OUTPUTS_ENV})"


def notebook_figures_dir(profile: Profile) -> Path:
    """Where a notebook saves what it draws: the results' figures folder, except over the
    published results, whose figures only `make publish` and `make figures` write."""
    if renders_published(profile):
        return artifacts_dir() / "notebooks" / profile.name
    return figures.figures_dir(profile.name)


def show(fig, profile: Profile, name: str) -> None:
    """Save `fig` as `name` (PNG, PDF) in `notebook_figures_dir` and display it once; a
    figure that does not exist (None: no run of its section) is said so instead."""
    from IPython.display import display

    if fig is None:
        print(f"{name}: profile {profile.name} has no runs for this figure")
        return
    figures.save(fig, notebook_figures_dir(profile), name)
    display(fig)


def run_grid(profile: Profile, backend: str, methods: tuple[str, ...] | None = None) -> None:
    """A notebook's sweep: run what is not done yet, or nothing over the published results."""
    from gcdt.experiments.sweep import sweep

    if renders_published(profile):
        print(
            f"rendering the published {profile.name} results: `make reproduce "
            f"PROFILE={profile.name}` re-runs them into a folder of your own"
        )
        return
    summary = sweep(profile, backend=backend, methods=methods, progress=False)
    print(summary.line())
    if not summary.ok:
        raise GcdtError(
            f"{summary.line()}: see the failed result files in {results_dir(profile.name)}/runs"
        )


def write_tables(profile: Profile, runs) -> list[Path]:
    out = results_dir(profile.name)
    written = []
    for name, table, caption in (
        ("table1", tables.table1(runs), "Performance comparison: Return / Success Rate (\\%)"),
        (
            "ablation",
            tables.ablation_table(runs),
            "Goal conditioning ablation: Return / Success Rate (\\%)",
        ),
    ):
        if table.empty:
            continue
        for ext, text in (
            ("csv", table.to_csv(index=False, float_format="%.4f")),
            ("md", tables.to_markdown(table, paper=name == "table1") + "\n"),
            ("tex", tables.to_latex(table, caption, f"tab:{name}")),
        ):
            write_if_changed(out / f"{name}.{ext}", text)
            written.append(out / f"{name}.{ext}")
    for name, (section, x) in tables.CURVES.items():  # Fig. 3 and Fig. 4's points
        curve = tables.curve_table(runs, section, x)
        if curve.empty:
            continue
        for ext, text in (
            ("csv", curve.to_csv(index=False, float_format="%.4f")),
            ("md", tables.curve_markdown(curve, x) + "\n"),
        ):
            write_if_changed(out / f"{name}.{ext}", text)
            written.append(out / f"{name}.{ext}")
    study = targets.target_table(runs)
    if not study.empty:  # the return-target study, where the profile makes it
        best = targets.best_targets(runs)
        for name, text in (
            ("return_target.csv", study.to_csv(index=False, float_format="%.4f")),
            ("best_target.csv", best.to_csv(index=False, float_format="%.4f")),
            ("best_target.md", targets.best_targets_markdown(best) + "\n"),
        ):
            write_if_changed(out / name, text)
            written.append(out / name)
    regions = generalisation.generalisation_table(runs)
    if not regions.empty:  # the goal-generalisation study, where the profile makes it
        for name, text in (
            ("generalisation.csv", regions.to_csv(index=False, float_format="%.4f")),
            ("generalisation.md", generalisation.generalisation_markdown(regions) + "\n"),
        ):
            write_if_changed(out / name, text)
            written.append(out / name)
    return written


def write_figures(profile: Profile, runs) -> list[Path]:
    """Fig. 2-4 and the learning curves, each drawn from the run results alone."""
    out = figures.figures_dir(profile.name)
    written = []
    for name, make in (
        ("fig2_architecture", figures.table1_architecture_figure),
        ("fig3_dataset_size", figures.dataset_size_figure),
        ("fig4_expert_ratio", figures.expert_ratio_figure),
        ("tqc_learning_curves", figures.tqc_learning_curves_figure),
        ("training_loss", figures.training_loss_figure),
        ("return_target", targets.target_figure),
        ("goal_generalisation", generalisation.generalisation_figure),
    ):
        fig = make(runs)
        if fig is not None:
            written += figures.save(fig, out, name)
    return written


def write_report(profile: Profile) -> list[Path]:
    """Every table and results figure of `profile` from its run results; the paths written."""
    runs = tables.load_runs(profile)
    written = write_tables(profile, runs) + write_figures(profile, runs)
    report = results_dir(profile.name) / "report.md"
    table1 = tables.to_markdown(tables.table1(runs))
    write_if_changed(
        report,
        f"# Results: profile `{profile.name}`\n\n"
        f"Generated by `gcdt report --profile {profile.name}` from "
        f"`results/{profile.name}/runs/` ({len(runs)} finished runs).\n\n"
        f"{deviations_text(profile)}\n\n"
        "## Table 1: return / success rate (%), mean ± std over seeds [95 % bootstrap "
        "interval of the success rate over seeds]\n\n"
        f"{table1}\n",
    )
    return [*written, report]


def record_reproduction(
    profile: Profile, wall_seconds: float, backend: str, *, measured_at: dt.datetime | None = None
) -> Path:
    """Write results/<profile>/reproduce.json: how long `make reproduce` took, and where.

    A reproduction that resumes an interrupted one finds some runs done: the record counts
    them and their own run time, so that the wall time is never read as the whole work's.
    `measured_at` is when `wall_seconds` was taken (default now): the reproduction started
    `wall_seconds` before it, and a run that finished before that start was already done.
    """
    from gcdt.provenance import git_commit, machine_info, utc_now

    if not wall_seconds >= 0:
        raise GcdtError(f"wall time must be >= 0 seconds, got {wall_seconds}")
    runs = tables.load_runs(profile)
    started = (measured_at or dt.datetime.now(dt.UTC)) - dt.timedelta(seconds=wall_seconds)
    seconds = [float(e.get("seconds", {}).get("total_seconds", 0.0)) for e in runs["execution"]]
    earlier = [
        s
        for e, s in zip(runs["execution"], seconds, strict=True)
        if "finished" in e and dt.datetime.fromisoformat(e["finished"]) < started
    ]
    record = {
        "command": f"make reproduce PROFILE={profile.name} BACKEND={backend}",
        "wall_seconds": round(float(wall_seconds), 1),
        "finished": utc_now(),
        "git_commit": git_commit(),
        "runs": len(runs),
        "run_seconds": round(sum(seconds), 1),  # the runs' own times added up: the work
        "earlier_runs": len(earlier),  # already done when this reproduction started
        "earlier_run_seconds": round(sum(earlier), 1),
        "machine": machine_info(),
    }
    path = results_dir(profile.name) / "reproduce.json"
    write_json_atomic(path, record)
    return path


def _wall_time_text(profile: Profile) -> str:
    path = results_dir(profile.name) / "reproduce.json"
    if not path.exists():
        return "No wall time recorded: these results were not made by `make reproduce`."
    record = json.loads(path.read_text())
    minutes = record["wall_seconds"] / 60
    machine = record["machine"]
    text = (
        f"Wall time of `{record['command']}` (notebooks, runs and report; environment "
        f"install excluded): **{minutes:.0f} min** on {machine['cores']} cores "
        f"({machine['cpu']}), {record['runs']} runs, finished {record['finished']} at "
        f"commit {str(record['git_commit'])[:12]}."
    )
    if "run_seconds" in record:
        text += f" The runs' own times add up to {record['run_seconds'] / 3600:.1f} h of work."
    if record.get("earlier_runs"):
        text += (
            f" {record['earlier_runs']} runs ({record['earlier_run_seconds'] / 3600:.1f} h of "
            "their own time) were already done when it started (an interrupted reproduction, "
            "resumed) and are not in its wall time."
        )
    for other, count in _shared_runs(profile).items():
        text += (
            f" {count} of its run files are the `{other}` profile's, byte for byte: the same "
            "run keys (the same specs), done once for both."
        )
    return text


def _shared_runs(profile: Profile) -> dict[str, int]:
    """Other profiles' results that hold some of `profile`'s run files, identical: how many."""
    own = sorted((results_dir(profile.name) / "runs").glob("*.json"))
    shared = {}
    for other in PROFILES:
        theirs = results_dir(other) / "runs"
        if other == profile.name or not theirs.is_dir():
            continue
        count = sum(
            1
            for path in own
            if (theirs / path.name).is_file()
            and (theirs / path.name).read_bytes() == path.read_bytes()
        )
        if count:
            shared[other] = count
    return shared


#: The README's figures, where the profile makes them, each followed by its numbers.
README_FIGURES = {
    "fig3_dataset_size": "Fig. 3: success rate vs dataset size (RQ4)",
    "fig4_expert_ratio": "Fig. 4: success rate vs expert share (RQ5)",
    "return_target": "Return-target study (ours): success vs the target return",
    "goal_generalisation": (
        "Goal generalisation (ours): success inside vs outside the training goals' region"
    ),
}


def _points_markdown(fig: str, runs) -> str:
    """The numbers behind one of README_FIGURES, as Markdown (success and 95 % interval over
    seeds): the curve's points, the best target return, or success inside vs outside."""
    if fig in tables.CURVES:
        section, x = tables.CURVES[fig]
        return tables.curve_markdown(tables.curve_table(runs, section, x), x)
    if fig == "return_target":
        return targets.best_targets_markdown(targets.best_targets(runs))
    return generalisation.generalisation_markdown(generalisation.generalisation_table(runs))


def readme_block(profile: Profile) -> str:
    """The README's results section, all generated from results/<profile>/: Table 1 beside
    the paper's values, where ours and the paper's point in different directions, the
    ablation, Fig. 3 and 4 and the two studies' figures with their numbers, the wall time and
    the profile's deviations."""
    runs = tables.load_runs(profile)
    name = profile.name
    parts = [
        f"Generated by `gcdt report --profile {name} --readme` from `results/{name}/`. "
        + _wall_time_text(profile),
        f"**Table 1** as reproduced by the `{name}` profile (return / success rate in %, "
        "mean ± std over seeds, the success rate's 95 % bootstrap interval over seeds in "
        "brackets; the paper's values in parentheses):",
        tables.to_markdown(tables.table1(runs)),
        "**Direction checks**: each comparison the paper's results make, with ours (success "
        f"rates; differences under {tables.EQUAL_POINTS:g} point count as equal):",
        tables.directions_markdown(runs),
    ]
    ablation = tables.ablation_table(runs)
    if not ablation.empty:
        parts += [
            "**Goal-conditioning ablation** (ours; not in the paper), same data:",
            tables.to_markdown(ablation, paper=False),
        ]
    for fig, caption in README_FIGURES.items():
        if (figures.figures_dir(name) / f"{fig}.png").exists():
            parts += [f"![{caption}](figures/{name}/{fig}.png)", _points_markdown(fig, runs)]
    parts.append(deviations_text(profile))
    return "\n\n".join(parts)


def update_readme(profile: Profile, readme: Path) -> None:
    """README's results block regenerated from the published results (rewritten only if it
    changes). Refused for a reproduction's own folder: the README shows published numbers."""
    if not is_published():
        raise GcdtError(
            f"--readme shows the published results, but results are read from "
            f"{outputs_root()} (${OUTPUTS_ENV}): unset {OUTPUTS_ENV}, or publish first"
        )
    write_between_markers(readme, README_START, README_END, readme_block(profile))


__all__ = [
    "check_parameters",
    "figures",
    "notebook_figures_dir",
    "outputs_note",
    "readme_block",
    "record_reproduction",
    "renders_published",
    "run_grid",
    "show",
    "tables",
    "update_readme",
    "write_report",
]
