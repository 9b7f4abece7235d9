"""A user's reproduction against the published results: the check, and publishing a run.

`make reproduce` runs a profile's grid into a working folder of its own (`$GCDT_OUTPUTS`,
default `artifacts/reproduce/`), never into `results/<profile>/`, and ends with
`reproduction_check`: for every Table 1 cell, ablation cell and Fig. 3 / Fig. 4 point, the
published value with its 95 % interval, the user's value, the difference, and whether the
user's value lies inside the published interval. `publish` (maintainers, `make publish`)
makes a finished working run the new published results.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from gcdt.errors import GcdtError
from gcdt.experiments.grid import build_grid
from gcdt.experiments.profiles import Profile
from gcdt.experiments.release import MANIFEST_NAME
from gcdt.experiments.store import RunStore
from gcdt.paths import REPO_ROOT, figures_dir, results_dir, write_if_changed
from gcdt.report import tables

CHECK_NAME = "reproduction_check"
#: Values within this of an interval's edge count as inside it (rounding of stored floats).
TOLERANCE = 1e-9


def _points(runs: pd.DataFrame) -> pd.DataFrame:
    """Every value the tables and figures show, with its 95 % interval: one row per item and
    metric (success in %, return)."""
    rows = []

    def add(item: str, cell: pd.Series, metrics: tuple[str, ...]) -> None:
        for metric in metrics:
            rows.append(
                {
                    "item": item,
                    "metric": metric,
                    "value": cell[f"{metric}_mean"],
                    "low": cell[f"{metric}_ci_low"],
                    "high": cell[f"{metric}_ci_high"],
                }
            )

    def where(task: str, reward: str) -> str:
        return f"{tables.TASK_NAMES[task]} {reward}"

    for _, c in tables.table1(runs).iterrows():
        add(
            f"Table 1: {tables.METHOD_NAMES[c['method']]}, {where(c['task'], c['reward'])}",
            c,
            ("success", "return"),
        )
    ablation = tables.ablation_table(runs)
    for _, c in ablation[ablation["method"] != "gcdt"].iterrows():
        add(
            f"Ablation: {tables.METHOD_NAMES[c['method']]}, {where(c['task'], c['reward'])}",
            c,
            ("success", "return"),
        )
    for (section, x), label in zip(tables.CURVES.values(), ("Fig. 3", "Fig. 4"), strict=True):
        for _, c in tables.curve_table(runs, section, x).iterrows():
            at = f"{int(c[x]):,} transitions" if x == "size" else f"{100 * c[x]:.0f} % expert"
            add(f"{label}: {where(c['task'], c['reward'])}, {at}", c, ("success",))
    return pd.DataFrame(rows, columns=["item", "metric", "value", "low", "high"])


def reproduction_check(published: pd.DataFrame, ours: pd.DataFrame) -> pd.DataFrame:
    """Published value and interval, ours, the difference, and whether ours lies inside the
    published interval, for every item of the published tables and figures."""
    merged = _points(published).merge(
        _points(ours)[["item", "metric", "value"]].rename(columns={"value": "ours"}),
        on=["item", "metric"],
        how="left",
    )
    merged = merged.rename(columns={"value": "published"})
    merged["difference"] = merged["ours"] - merged["published"]
    merged["agrees"] = (merged["ours"] >= merged["low"] - TOLERANCE) & (
        merged["ours"] <= merged["high"] + TOLERANCE
    )
    return merged


def check_markdown(check: pd.DataFrame) -> str:
    """The check as a Markdown table, then one summary line."""
    unit = {"success": " %", "return": ""}
    lines = [
        "| item | metric | published [95 % interval] | ours | difference | agrees |",
        "|---|---|---|---|---|---|",
    ]
    for r in check.itertuples():
        ours = "missing" if np.isnan(r.ours) else f"{r.ours:.2f}{unit[r.metric]}"
        diff = "" if np.isnan(r.difference) else f"{r.difference:+.2f}"
        lines.append(
            f"| {r.item} | {r.metric} | {r.published:.2f}{unit[r.metric]} [{r.low:.2f}, "
            f"{r.high:.2f}] | {ours} | {diff} | {'yes' if r.agrees else '**no**'} |"
        )
    return "\n".join(lines) + "\n\n" + summary_line(check)


def summary_line(check: pd.DataFrame) -> str:
    success = check[check["metric"] == "success"]
    return (
        f"{int(check['agrees'].sum())} of {len(check)} values agree within the published 95 % "
        f"intervals (success rates: {int(success['agrees'].sum())} of {len(success)}; "
        f"missing: {int(check['ours'].isna().sum())})."
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
        "of the repository). "
        "An interval is the published value's 95 % interval: over seeds (bootstrap) when a "
        "cell has several, else over the evaluation episodes of its one run.\n\n"
        + check_markdown(check)
        + "\n"
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
