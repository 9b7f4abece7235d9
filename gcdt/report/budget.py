"""The budget check: does a fixed offline budget stop short of what longer training reaches?

A profile that trains for a fixed number of gradient steps instead of the paper's epochs
(`Profile.train_steps`) justifies it with its `budget` section: GC-DT on the first seed,
trained `Profile.budget_factor` times longer, beside the grid's run of the same task, reward,
seed and data at the budget (Table 1's at 100 % expert data, RQ5's at a mixture's share, and
each of them where Table 1 trains longer than the rest). The budget holds when the longer
run's success lies within the 95 % interval of the budget run's evaluation.

That interval is the evaluation's noise only. One longer seed cannot tell a change of budget
from a change of training seed, so the check also gives the range of the cell's seeds at the
budget: a change inside it is as large as the seeds already differ by.
"""

from __future__ import annotations

import pandas as pd

from gcdt.report.tables import TASK_NAMES, aggregate

#: The sections whose runs are the budget runs a longer one is set against.
_CELLS = {"table1", "rq4", "rq5"}


def budget_table(runs: pd.DataFrame, factor: int) -> pd.DataFrame:
    """Per task, reward, seed, expert share and budget of the check (the longer runs are
    `factor` times the budget): the budget run's and the longer run's steps and success with
    its 95 % interval, the change, whether the longer run's success lies within the budget
    run's interval, and the cell's seeds at the budget (their number and success range) with
    whether it lies within that (empty without a budget section)."""
    longer = runs[runs["sections"].apply(lambda s: "budget" in s)]
    cells = runs["sections"].apply(lambda s: bool(_CELLS & set(s)))
    rows = []
    for r in longer.itertuples():
        cell = runs[
            cells
            & (runs["method"] == r.method)
            & (runs["task"] == r.task)
            & (runs["reward"] == r.reward)
            & (runs["size"] == r.size)
            & (runs["expert_ratio"] == r.expert_ratio)
            & (runs["train_steps"] * factor == r.train_steps)
        ]
        base = cell[cell["seed"] == r.seed]
        if base.empty:
            continue  # the budget run is not done yet
        b, x = aggregate(base, ["task"]).iloc[0], aggregate(longer.loc[[r.Index]], ["task"]).iloc[0]
        seeds = 100 * cell["success_rate"]
        rows.append(
            {
                "task": r.task,
                "reward": r.reward,
                "seed": r.seed,
                "expert_ratio": r.expert_ratio,
                "steps": int(base["train_steps"].iloc[0]),
                "success": b["success_mean"],
                "success_ci_low": b["success_ci_low"],
                "success_ci_high": b["success_ci_high"],
                "longer_steps": int(r.train_steps),
                "longer_success": x["success_mean"],
                "longer_ci_low": x["success_ci_low"],
                "longer_ci_high": x["success_ci_high"],
                "change": x["success_mean"] - b["success_mean"],
                "within": bool(b["success_ci_low"] <= x["success_mean"] <= b["success_ci_high"]),
                "seeds": len(cell),
                "seeds_low": seeds.min(),
                "seeds_high": seeds.max(),
                "within_seeds": bool(seeds.min() <= x["success_mean"] <= seeds.max()),
            }
        )
    return pd.DataFrame(rows)


def budget_markdown(table: pd.DataFrame) -> str:
    """`budget_table` as Markdown: one row per check."""
    lines = [
        "| task | reward | seed | expert % | steps | success % [95 %] | longer: steps "
        "| success % [95 %] | change (pts) | within the budget run's interval "
        "| the cell's seeds at the budget: success % range | within that range |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in table.itertuples():
        lines.append(
            f"| {TASK_NAMES[r.task]} | {r.reward} | {r.seed} | {100 * r.expert_ratio:.0f} | "
            f"{r.steps:,} | {r.success:.1f} "
            f"[{r.success_ci_low:.1f}, {r.success_ci_high:.1f}] | {r.longer_steps:,} | "
            f"{r.longer_success:.1f} [{r.longer_ci_low:.1f}, {r.longer_ci_high:.1f}] | "
            f"{r.change:+.1f} | {'yes' if r.within else '**no**'} | "
            f"{r.seeds_low:.1f}-{r.seeds_high:.1f} ({r.seeds} seeds) | "
            f"{'yes' if r.within_seeds else '**no**'} |"
        )
    return "\n".join(lines)
