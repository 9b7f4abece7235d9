"""The return-target study (not in the paper): what the target return does to a GC-DT.

The paper conditions every evaluation on a target return of 0. The grid's `targets` section
evaluates each Table 1 GC-DT checkpoint at a range of targets (`Profile.return_targets`),
every run on two held-out evaluation seeds: a validation one and a test one
(`gcdt.experiments.profiles.target_seeds`). The curve is drawn from the test evaluations;
the best target is chosen on the validation evaluations (mean success over training seeds,
then return) and scored on the test ones, so its number is not tuned on its own test.
"""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from gcdt.errors import GcdtError
from gcdt.report.figures import reward_panels
from gcdt.report.tables import TASK_NAMES, aggregate

#: Index of each split in a study run's evaluations (its `eval_seeds` order).
SPLITS = {"validation": 0, "test": 1}


def study_runs(runs: pd.DataFrame, split: str) -> pd.DataFrame:
    """The study's runs with `success_rate`, `mean_return`, `std_return` and `episodes` of
    their `split` evaluation alone (None when the profile has no study runs)."""
    if split not in SPLITS:
        raise GcdtError(f"unknown split {split!r}: expected one of {', '.join(SPLITS)}")
    sel = runs[runs["sections"].apply(lambda s: "targets" in s)]
    if sel.empty:
        return sel
    evaluation = sel["evaluations"].apply(lambda e: e[SPLITS[split]])
    return sel.assign(
        **{
            name: evaluation.apply(lambda e, name=name: e[name])
            for name in ("success_rate", "mean_return", "std_return", "episodes")
        }
    )


def target_table(runs: pd.DataFrame) -> pd.DataFrame:
    """Per reward, task and target return: success and return on the test seeds, mean, std
    and 95 % interval over training seeds."""
    test = study_runs(runs, "test")
    if test.empty:
        return pd.DataFrame()
    table = aggregate(test, ["reward", "task", "target_return"])
    return table.sort_values(["reward", "task", "target_return"], ascending=[False, True, False])


def best_targets(runs: pd.DataFrame) -> pd.DataFrame:
    """Per reward and task: the target with the best validation success (then return), and
    the test success and return at that target and at the paper's 0, over training seeds."""
    val, test = study_runs(runs, "validation"), study_runs(runs, "test")
    if val.empty:
        return pd.DataFrame()
    rows = []
    for (reward, task), cell in val.groupby(["reward", "task"], sort=False):
        means = cell.groupby("target_return")[["success_rate", "mean_return"]].mean()
        # Ties go to the target nearest the paper's 0 (the stable sort keeps that order).
        means = means.sort_index(ascending=False)
        ranked = means.sort_values(["success_rate", "mean_return"], ascending=False, kind="stable")
        best = ranked.index[0]
        row = {"reward": reward, "task": task, "best_target": best}
        for name, target in (("best", best), ("zero", 0.0)):
            chosen = test[
                (test["reward"] == reward)
                & (test["task"] == task)
                & (test["target_return"] == target)
            ]
            if chosen.empty:
                continue
            stats = aggregate(chosen, ["task"]).iloc[0]
            for metric in ("success_mean", "success_ci_low", "success_ci_high", "return_mean"):
                row[f"{name}_{metric}"] = stats[metric]
        rows.append(row)
    return pd.DataFrame(rows)


def best_targets_markdown(table: pd.DataFrame) -> str:
    """`best_targets` as a Markdown table (success %, 95 % interval over seeds)."""
    lines = [
        "| reward | task | best target (validation) | test success at it | test success at 0 |",
        "|---|---|---|---|---|",
    ]
    for _, r in table.iterrows():
        cells = [
            f"{r[f'{n}_success_mean']:.1f} [{r[f'{n}_success_ci_low']:.1f}, "
            f"{r[f'{n}_success_ci_high']:.1f}] (return {r[f'{n}_return_mean']:.2f})"
            if not np.isnan(r.get(f"{n}_success_mean", np.nan))
            else "–"
            for n in ("best", "zero")
        ]
        lines.append(
            f"| {r['reward']} | {TASK_NAMES[r['task']]} | {r['best_target']:g} | "
            + " | ".join(cells)
            + " |"
        )
    return "\n".join(lines)


def target_figure(runs: pd.DataFrame) -> plt.Figure | None:
    """Success rate (top) and return (bottom) against the target return on the test seeds:
    one column per reward, one line per task, 95 % intervals over training seeds (None
    when the profile has no study runs)."""
    table = target_table(runs)
    if table.empty:
        return None
    fig, axes, rewards = reward_panels(set(table["reward"]), rows=2, height=6.4, sharex="col")
    for col, reward in enumerate(rewards):
        for task in TASK_NAMES:
            cell = table[(table["reward"] == reward) & (table["task"] == task)]
            if cell.empty:
                continue
            x = cell["target_return"]
            for row, name in enumerate(("success", "return")):
                mean = cell[f"{name}_mean"].to_numpy()
                axes[row][col].errorbar(
                    x,
                    mean,
                    yerr=[mean - cell[f"{name}_ci_low"], cell[f"{name}_ci_high"] - mean],
                    marker="o",
                    capsize=3,
                    label=TASK_NAMES[task],
                )
        axes[0][col].set_title(f"{reward.capitalize()} reward")
        axes[0][col].set_ylim(-5, 105)
        axes[1][col].set_xlabel("Target return at the episode's start")
        for row in (0, 1):
            axes[row][col].axvline(0.0, color="grey", lw=0.8, ls=":")  # the paper's target
            axes[row][col].grid(alpha=0.3)
        axes[0][col].legend()
    axes[0][0].set_ylabel("Success rate (%)")
    axes[1][0].set_ylabel("Mean return")
    fig.suptitle("GC-DT against its target return (test seeds)", y=1.02)
    fig.tight_layout()
    return fig
