"""The README's results section, generated from the published results of one profile:
`gcdt report --readme`, with the wall time `make reproduce` recorded (`record_reproduction`)."""

from __future__ import annotations

import datetime as dt
import json
from pathlib import Path

from gcdt.errors import GcdtError
from gcdt.experiments.profiles import PROFILES, Profile, deviations_text, get_profile
from gcdt.paths import (
    OUTPUTS_ENV,
    is_published,
    outputs_root,
    results_dir,
    write_between_markers,
    write_json_atomic,
)
from gcdt.report import budget, fidelity, figures, generalisation, tables, targets

README_START, README_END = "<!-- results:start -->", "<!-- results:end -->"


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
    runs = tables.load_runs(profile, agents=False)  # published agents: not this work
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


def wall_time_text(profile: Profile) -> str:
    """What `profile`'s results cost, from results/<profile>/reproduce.json: the wall time of
    the `make reproduce` that made them, where, and the runs' own times added up (else where
    to find an estimate). The one place a profile's measured cost is printed."""
    path = results_dir(profile.name) / "reproduce.json"
    if not path.exists():
        return (
            "No wall time recorded: these results were not made by `make reproduce` "
            f"(`gcdt sweep --profile {profile.name} --dry-run` estimates what it takes)."
        )
    record = json.loads(path.read_text())
    minutes = record["wall_seconds"] / 60
    machine = record["machine"]
    where = (
        f"on {machine['cores']} cores ({machine['cpu']}), {record['runs']} runs, finished "
        f"{record['finished']} at commit {str(record['git_commit'])[:12]}."
    )
    if record.get("earlier_runs"):
        # A resumed invocation's wall time is not the reproduction's: say which it is.
        text = (
            f"The last invocation of `{record['command']}` resumed an interrupted "
            f"reproduction: {record['earlier_runs']} runs "
            f"({record['earlier_run_seconds'] / 3600:.1f} h of their own time) were done "
            f"before it, and it took **{minutes:.0f} min** for the rest (runs, notebooks and "
            f"report; environment install excluded) {where}"
        )
    else:
        text = (
            f"Wall time of `{record['command']}` (runs, notebooks and report; environment "
            f"install excluded): **{minutes:.0f} min** {where}"
        )
    if "run_seconds" in record:
        text += f" The runs' own times add up to {record['run_seconds'] / 3600:.1f} h of work."
    for other, count in _shared_runs(profile).items():
        text += (
            f" {count} of its run files are the `{other}` profile's, byte for byte: the same "
            "run keys (the same specs), done once for both."
        )
    return text


def grid_status_text(profile: Profile, runs) -> str:
    """How far `profile`'s grid is, `runs` being its `load_runs`: its finished and planned
    runs, the published agents beside them, and what the runs cost (their own times: a
    measurement, where the dry run is an estimate): so far, for a grid still running; in all,
    with the agents' training, for a finished one that no `make reproduce` timed."""
    done, planned = tables.progress(runs, profile)
    agents = len(runs) - done
    text = f"{done} of {planned} runs finished" + (
        f", and {agents} published agents" if agents else ""
    )
    is_agent = runs["key"].str.startswith(tables.AGENT_KEY)
    spent = sum(
        e.get("seconds", {}).get("total_seconds", 0.0) for e in runs[~is_agent]["execution"]
    )
    if done >= planned and not (results_dir(profile.name) / "reproduce.json").exists():
        text += (
            f"; its runs' own times add up to {spent / 3600:.1f} h (one core each, shared "
            "datasets included, work lost to a stop not counted)"
        )
        core_hours = [e.get("core_hours") for e in runs[is_agent]["execution"]]
        if core_hours and None not in core_hours:
            text += f", and training its published agents {sum(core_hours):.1f} core-hours"
    if done < planned:
        text += (
            f"; the grid is still running (its finished runs took {spent / 3600:.1f} h of their"
            " own time, shared datasets included), and a cell is the mean of the seeds done so"
            f" far (`gcdt sweep --profile {profile.name} --dry-run` lists the rest, with their"
            " cost)"
        )
    return text


def sections_text(profile: Profile, runs) -> str:
    """For a grid still running, its sections as `tables.sections_left` lists them (empty for
    a finished grid): a section that did not fit is listed as not run, with its cost."""
    done, planned = tables.progress(runs, profile)
    if done >= planned:
        return ""
    return (
        "**The grid's sections**, in the order the sweep runs them (a run counts in the first "
        "section that needs it; the rest's cost is the dry run's estimate from the published "
        "runs' timings, collections excluded):\n\n"
        + tables.sections_left_markdown(tables.sections_left(profile))
    )


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


#: The profiles whose direction checks the README sets side by side, smallest first (smoke's
#: numbers mean nothing; paper's grid does not run on this machine).
DIRECTION_PROFILES = ("quick", "standard", "large")
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
    the paper's values, where ours and the paper's point in different directions, Table 1
    in every profile (smallest first), the ablation, Fig. 3 and 4 and the two studies'
    figures with their numbers, the wall time and the profile's deviations."""
    runs = tables.load_runs(profile)
    name = profile.name
    _own = [] if name in DIRECTION_PROFILES else [name]  # smallest first, this one included
    parts = [
        f"Generated by `gcdt report --profile {name} --readme` from `results/{name}/` "
        f"({grid_status_text(profile, runs)}). " + wall_time_text(profile),
        *filter(None, [sections_text(profile, runs)]),
        f"**Table 1** as reproduced by the `{name}` profile (return / success rate in %, "
        "mean ± std over seeds, the success rate's 95 % bootstrap interval over seeds in "
        "brackets; the paper's values in parentheses):",
        tables.to_markdown(tables.table1(runs)),
        "**Direction checks**: each comparison the paper's results make, with ours in every "
        "profile that has published results, smallest first (success rates; differences "
        f"under {tables.EQUAL_POINTS:g} point count as equal; bold: the other direction than "
        "the paper's; --: the profile does not make that comparison):",
        tables.directions_across_markdown(
            [profile if n == name else get_profile(n) for n in (*DIRECTION_PROFILES, *_own)]
        ),
    ]
    parts += [
        "**Table 1 at every scale**: each cell's return / success rate (%) in every profile "
        "that has published it with all its seeds, smallest first, beside the paper's:",
        tables.table1_across_markdown(
            [profile if n == name else get_profile(n) for n in (*DIRECTION_PROFILES, *_own)]
        ),
    ]
    cells = fidelity.fidelity_table(runs)
    if not cells.empty:
        parts += [f"**{fidelity.CAPTION}**:", fidelity.fidelity_markdown(cells)]
    checks = budget.budget_table(runs, profile.budget_factor)
    if not checks.empty:
        parts += [
            f"**Budget check**: GC-DT trained {profile.budget_factor} times longer than a "
            "fixed budget of the profile, beside the grid's run of the same data at that "
            "budget (success on the same evaluation):",
            budget.budget_markdown(checks),
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
