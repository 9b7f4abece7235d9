"""A user's reproduction against the published results: the check, and publishing a run.

`make reproduce` runs a profile's grid into a working folder of its own (`$GCDT_OUTPUTS`,
default `artifacts/reproduce/`), never into `results/<profile>/`, and ends with
`reproduction_check`: for every Table 1 cell, ablation cell and Fig. 3 / Fig. 4 point, the
published value, the user's, their difference with its 95 % interval (Welch's t over both
runs' seeds), and whether that interval contains 0. `publish` (maintainers, `make publish`)
makes a finished working run the new published results.

Why the difference's interval and not the published value's: the published value's interval
holds the published mean's uncertainty only, and a re-run's mean has as much of its own, so an
honest re-run would fall outside it far more often than its level says.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
from scipy import stats

from gcdt.errors import GcdtError
from gcdt.experiments.grid import build_grid
from gcdt.experiments.profiles import Profile
from gcdt.experiments.release import MANIFEST_NAME
from gcdt.experiments.store import RunStore
from gcdt.paths import REPO_ROOT, figures_dir, results_dir, write_if_changed
from gcdt.report import tables
from gcdt.report.tables import Sample

CHECK_NAME = "reproduction_check"
#: The confidence level of the difference's interval: an honest re-run disagrees on about
#: 1 - LEVEL of its values by chance.
LEVEL = 0.95
#: A difference within this of its interval counts as inside it (rounding of stored floats).
TOLERANCE = 1e-9
COLUMNS = ["item", "metric", "published", "ours", "difference", "diff_low", "diff_high", "over"]


def _level() -> str:
    return f"{100 * LEVEL:.0f} %"


def _chance() -> str:
    """How often an honest re-run's value disagrees by chance, in words ("1 in 20")."""
    return f"1 in {round(1 / (1 - LEVEL))}"


def welch_interval(ours: Sample, published: Sample) -> tuple[float, float]:
    """The LEVEL interval of `ours.mean - published.mean` by Welch's t (no equal spreads
    assumed; Welch-Satterthwaite degrees of freedom). The difference itself when neither side
    has spread; NaN when a side's spread is unknown."""
    difference = ours.mean - published.mean
    a, b = ours.std**2 / ours.n, published.std**2 / published.n  # squared standard errors
    if a + b == 0:
        return difference, difference
    df = (a + b) ** 2 / (a**2 / (ours.n - 1) + b**2 / (published.n - 1))
    half = stats.t.ppf(0.5 + LEVEL / 2, df) * np.sqrt(a + b)
    return float(difference - half), float(difference + half)


def _samples(runs: pd.DataFrame) -> pd.DataFrame:
    """Every value the tables and figures show, with its `tables.Sample` (what its mean is a
    mean of): one row per item and metric (success in %, return)."""
    rows = []

    def add(item: str, cell: pd.Series, metrics: tuple[str, ...]) -> None:
        for metric in metrics:
            rows.append({"item": item, "metric": metric, "sample": cell[f"{metric}_sample"]})

    def where(task: str, reward: str) -> str:
        return f"{tables.TASK_NAMES[task]} {reward}"

    for _, c in tables.table1(runs, samples=True).iterrows():
        add(
            f"Table 1: {tables.METHOD_NAMES[c['method']]}, {where(c['task'], c['reward'])}",
            c,
            ("success", "return"),
        )
    ablation = tables.ablation_table(runs, samples=True)
    for _, c in ablation[ablation["method"] != "gcdt"].iterrows():
        add(
            f"Ablation: {tables.METHOD_NAMES[c['method']]}, {where(c['task'], c['reward'])}",
            c,
            ("success", "return"),
        )
    for (section, x), label in zip(tables.CURVES.values(), ("Fig. 3", "Fig. 4"), strict=True):
        for _, c in tables.curve_table(runs, section, x, samples=True).iterrows():
            at = f"{int(c[x]):,} transitions" if x == "size" else f"{100 * c[x]:.0f} % expert"
            add(f"{label}: {where(c['task'], c['reward'])}, {at}", c, ("success",))
    return pd.DataFrame(rows, columns=["item", "metric", "sample"])


def _compare(published: Sample | None, ours: Sample | None) -> dict:
    """One item's columns of the check (NaN where a side has no value)."""
    if published is None or ours is None:
        mean = published.mean if published is not None else np.nan
        return dict.fromkeys(COLUMNS[3:], np.nan) | {"published": mean, "over": ""}
    low, high = welch_interval(ours, published)
    over = published.over if published.over == ours.over else f"{published.over} / {ours.over}"
    return {
        "published": published.mean,
        "ours": ours.mean,
        "difference": ours.mean - published.mean,
        "diff_low": low,
        "diff_high": high,
        "over": over,
    }


def reproduction_check(published: pd.DataFrame, ours: pd.DataFrame) -> pd.DataFrame:
    """For every item of the published tables and figures: the published value, ours, the
    difference (ours - published) with its LEVEL interval (Welch's t over both runs' seeds;
    over its evaluation episodes for a side with one seed; `over` says which, published /
    ours when they differ), and whether that interval contains 0. A missing value never
    agrees; a value whose spread is unknown agrees only when it equals the published one."""
    merged = _samples(published).merge(
        _samples(ours).rename(columns={"sample": "ours_sample"}), on=["item", "metric"], how="left"
    )
    check = pd.DataFrame(
        [
            {"item": item, "metric": metric, **_compare(p, o if isinstance(o, Sample) else None)}
            for item, metric, p, o in merged.itertuples(index=False)
        ],
        columns=COLUMNS,
    )
    inside = (check["diff_low"] <= TOLERANCE) & (check["diff_high"] >= -TOLERANCE)
    unknown = check["diff_low"].isna() & (check["difference"].abs() <= TOLERANCE)
    check["agrees"] = inside | unknown
    return check


def check_markdown(check: pd.DataFrame) -> str:
    """The check as a Markdown table, then one summary line."""
    unit = {"success": " %", "return": ""}
    lines = [
        f"| item | metric | published | ours | difference [{_level()} interval] | over | agrees |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in check.itertuples():
        ours = "missing" if np.isnan(r.ours) else f"{r.ours:.2f}{unit[r.metric]}"
        diff = "" if np.isnan(r.difference) else f"{r.difference:+.2f}"
        if not np.isnan(r.diff_low):
            diff += f" [{r.diff_low:+.2f}, {r.diff_high:+.2f}]"
        elif diff:
            diff += " [no spread known]"
        lines.append(
            f"| {r.item} | {r.metric} | {r.published:.2f}{unit[r.metric]} | {ours} | {diff} "
            f"| {r.over} | {'yes' if r.agrees else '**no**'} |"
        )
    return "\n".join(lines) + "\n\n" + summary_line(check)


#: Below this chance of as many disagreements in an honest re-run, the summary says to look
#: for a regression.
SUSPECT = 0.01


def chance_of_as_many(disagree: int, values: int) -> float:
    """The probability that an honest re-run disagrees on `disagree` or more of `values`
    values, each disagreeing with probability 1 - LEVEL on its own (binomial tail)."""
    return float(stats.binom.sf(disagree - 1, values, 1 - LEVEL)) if disagree else 1.0


def summary_line(check: pd.DataFrame) -> str:
    """How many values agree, what agreeing means, how many disagree by chance, and whether
    as many disagreements as these are likely by chance at all."""
    success = check[check["metric"] == "success"]
    compared = check[check["ours"].notna()]
    disagree = int((~compared["agrees"].astype(bool)).sum())
    line = (
        f"{int(check['agrees'].sum())} of {len(check)} values agree: the {_level()} interval "
        "of the difference of means (ours - published), from both runs' seed spread (Welch), "
        f"contains 0 (success rates: {int(success['agrees'].sum())} of {len(success)}; "
        f"missing: {int(check['ours'].isna().sum())}). At that level about {_chance()} values "
        "of an honest re-run disagree by chance."
    )
    if not disagree:
        return line
    # Values are not quite independent (a cell's success and return move together), so the
    # tail is a guide, not a test of its own.
    chance = chance_of_as_many(disagree, len(compared))
    verdict = (
        "look for a regression (less training, a changed default)"
        if chance < SUSPECT
        else "as expected of an honest re-run"
    )
    return (
        f"{line} {disagree} or more of {len(compared)} disagree by chance with probability "
        f"{chance:.2g} (values counted as independent): {verdict}."
    )


def write_check(
    profile: Profile, ours_root: str | Path, published_root: str | Path = REPO_ROOT
) -> tuple[str, Path | None]:
    """Compare the runs under `ours_root` with the published ones; write
    `results/<profile>/reproduction_check.{csv,md}` under `ours_root`; return the Markdown
    (and the .md path, None when nothing is published to compare with)."""
    published_runs = results_dir(profile.name, published_root) / "runs"
    try:
        # The published agents' cells are not re-run: both sides would hold the same values.
        published = tables.load_runs(profile, published_runs, agents=False)
    except GcdtError:
        if profile.name == "smoke":
            why = "the smoke profile's numbers are never published"
        elif any(published_runs.glob("*.json")):
            why = "the published runs come from an earlier version of the grid, with other run keys"
        else:
            why = "none are published"
        return (
            f"No published results of profile {profile.name!r} in {published_runs}: nothing to "
            f"compare with ({why}).",
            None,
        )
    ours = tables.load_runs(profile, results_dir(profile.name, ours_root) / "runs", agents=False)
    check = reproduction_check(published, ours)
    out = results_dir(profile.name, ours_root)
    text = (
        f"# Reproduction check: profile `{profile.name}`\n\n"
        f"The runs of this reproduction against the published ones (`results/{profile.name}/` "
        f"of the repository). A value agrees when the {_level()} interval of the difference of "
        "means (ours - published), from both runs' seed spread (Welch's t interval), contains "
        "0; where a side has one seed, its spread is that run's evaluation episodes' (`over`). "
        f"At that level about {_chance()} values of an honest re-run (another CPU's floating "
        "point trains other policies) disagree by chance, scattered and of either sign; a "
        "regression (less training, a changed default) shows as a cluster of disagreements "
        "of one sign.\n\n" + check_markdown(check) + "\n"
    )
    write_if_changed(out / f"{CHECK_NAME}.csv", check.to_csv(index=False, float_format="%.4f"))
    path = out / f"{CHECK_NAME}.md"
    write_if_changed(path, text)
    return text, path


def publish(
    profile: Profile, source_root: str | Path, published_root: str | Path = REPO_ROOT
) -> tuple[list[Path], list[Path]]:
    """Make the finished reproduction under `source_root` the published results of `profile`:
    results/<profile>/ and figures/<profile>/ mirror the source's (files that did not change
    are left untouched, files the source lacks are removed). Returns (written, removed).

    Only a whole `make reproduce` qualifies: every run of the grid done, and its record
    (`reproduce.json`, written after the notebooks and the report) present.
    """
    source = results_dir(profile.name, source_root)
    store = RunStore(source / "runs")
    unfinished = [
        e.spec.label for e in build_grid(profile) if store.read(e.spec.key()).state != "done"
    ]
    if unfinished:
        raise GcdtError(
            f"{len(unfinished)} run(s) of profile {profile.name!r} are not done in {source} "
            f"(e.g. {unfinished[0]}): finish them with `make reproduce PROFILE={profile.name}` "
            "before publishing"
        )
    if not (source / "reproduce.json").is_file():
        raise GcdtError(
            f"{source} holds no reproduce.json: only a finished `make reproduce "
            f"PROFILE={profile.name}` (runs, notebooks, report) can be published"
        )
    written, removed = [], []
    for src, dst in (
        (source, results_dir(profile.name, published_root)),
        (figures_dir(profile.name, source_root), figures_dir(profile.name, published_root)),
    ):
        files = _mirrored(src)
        # The datasets' manifest is `make datasets`'s to write, not a reproduction's.
        for rel in sorted(_mirrored(dst) - files - {Path(MANIFEST_NAME)}):
            (dst / rel).unlink()
            removed.append(dst / rel)
        for rel in sorted(files):
            if write_if_changed(dst / rel, (src / rel).read_bytes()):
                written.append(dst / rel)
        for folder in sorted((d for d in dst.rglob("*") if d.is_dir()), reverse=True):
            if not any(folder.iterdir()):
                folder.rmdir()
    return written, removed


def _mirrored(root: Path) -> set[Path]:
    """The files under `root` that publishing mirrors: none hidden, none in a hidden folder
    (temp files, .ipynb_checkpoints)."""
    if not root.exists():
        return set()
    return {
        p.relative_to(root)
        for p in root.rglob("*")
        if p.is_file() and not any(part.startswith(".") for part in p.relative_to(root).parts)
    }
