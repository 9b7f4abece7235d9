"""The goal-generalisation study (not in the paper): do the learners reach goals they never saw?

The grid's `generalisation` section trains GC-DT and BC on expert data whose desired goals lie
in one region of the goal space (`Profile.goal_regions[0]`, e.g. one half of the table) and
evaluates each checkpoint with the paper's protocol inside that region and in another one
(`[1]`), on held-out seeds: the envs draw their goals from the region (`gcdt.regions`).
"""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from gcdt.regions import GoalRegion
from gcdt.report.figures import reward_panels
from gcdt.report.tables import METHOD_NAMES, TASK_NAMES, aggregate


def generalisation_table(runs: pd.DataFrame) -> pd.DataFrame:
    """Per reward, task, method and evaluation region: success and return, mean and 95 %
    interval over seeds (empty when the profile has no study runs)."""
    sel = runs[runs["sections"].apply(lambda s: "generalisation" in s)]
    if sel.empty:
        return pd.DataFrame()
    return aggregate(sel, ["reward", "task", "method", "eval_region", "train_region"])


def _region_cell(part: pd.DataFrame) -> str:
    """'success [95 % interval] at REGION' for one evaluation region's row, '–' without one."""
    if part.empty:
        return "–"
    row = part.iloc[0]
    region = GoalRegion.parse(row["eval_region"]).describe()
    return (
        f"{row['success_mean']:.1f} [{row['success_ci_low']:.1f}, "
        f"{row['success_ci_high']:.1f}] at {region}"
    )


def generalisation_markdown(table: pd.DataFrame) -> str:
    """One row per task and method: success inside the training region and outside it."""
    lines = [
        "| reward | task | method | trained on goals in | success there (%) "
        "| success elsewhere (%) |",
        "|---|---|---|---|---|---|",
    ]
    for (reward, task, method), rows in table.groupby(["reward", "task", "method"], sort=False):
        inside = rows["eval_region"] == rows["train_region"]
        trained_on = GoalRegion.parse(rows.iloc[0]["train_region"]).describe()
        lines.append(
            f"| {reward} | {TASK_NAMES[task]} | {METHOD_NAMES[method]} | {trained_on} | "
            f"{_region_cell(rows[inside])} | {_region_cell(rows[~inside])} |"
        )
    return "\n".join(lines)


def generalisation_figure(runs: pd.DataFrame) -> plt.Figure | None:
    """Success inside vs outside the training goals' region, per method and task: bars with
    95 % intervals, one panel per reward (None when the profile has no study runs)."""
    table = generalisation_table(runs)
    if table.empty:
        return None
    fig, axes, rewards = reward_panels(set(table["reward"]), width=6.0, height=3.8, sharey=True)
    for ax, reward in zip(axes[0], rewards, strict=True):
        block = table[table["reward"] == reward]
        groups = list(block.groupby(["task", "method"], sort=False))
        x = np.arange(len(groups))
        for offset, (where, color) in ((-0.2, ("inside", "C0")), (0.2, ("outside", "C1"))):
            means, lows, highs = [], [], []
            for _, rows in groups:
                same = rows["eval_region"] == rows["train_region"]
                row = rows[same if where == "inside" else ~same]
                mean = row["success_mean"].iloc[0] if len(row) else np.nan
                means.append(mean)
                lows.append(mean - row["success_ci_low"].iloc[0] if len(row) else 0.0)
                highs.append(row["success_ci_high"].iloc[0] - mean if len(row) else 0.0)
            label = "goals in the training region" if where == "inside" else "goals elsewhere"
            ax.bar(x + offset, means, width=0.4, color=color, label=label)
            ax.errorbar(x + offset, means, yerr=[lows, highs], fmt="none", ecolor="k", capsize=3)
        ax.set_xticks(
            x, [f"{TASK_NAMES[t]}\n{METHOD_NAMES[m]}" for (t, m), _ in groups], fontsize=8
        )
        ax.set_title(f"{reward.capitalize()} reward")
        ax.set_ylim(0, 105)
        ax.grid(alpha=0.3, axis="y")
        ax.legend(fontsize=8)
    axes[0][0].set_ylabel("Success rate (%)")
    fig.suptitle("Reaching goals outside the training data's region", y=1.02)
    fig.tight_layout()
    return fig
