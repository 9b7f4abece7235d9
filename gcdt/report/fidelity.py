"""How close GC-DT comes to the paper's Table 1, cell by cell, beside what its data allowed.

A cell meets the reproduction's targets when GC-DT's success lies within `SUCCESS_POINTS` of
the paper's and its return within `RETURN_SHARE` of the paper's (relative to its size). An
offline learner copies its data, so where a cell misses, the data's own success and return
(the collecting expert's, recorded by every run in `training.dataset`) say why: a return
better than the paper's from data that is better than the paper's is the data, not the method.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from gcdt.report.tables import TASK_NAMES, table1

SUCCESS_POINTS = 3.0  # success within 3 points of the paper's
RETURN_SHARE = 0.25  # return within 25 % of the paper's
CAPTION = (
    f"GC-DT against the paper's Table 1: success within {SUCCESS_POINTS:g} points and return"
    f" within {RETURN_SHARE * 100:g} % of the paper's (bold: missed; the return gap is a share of"
    " the paper's return, > 0 better), beside the data it learned from"
)


def fidelity_table(runs: pd.DataFrame) -> pd.DataFrame:
    """Per reward and task where GC-DT has Table 1 runs: its success and return beside the
    paper's, the gaps, the data's own success and return, and whether each target is met."""
    cells = table1(runs)
    cells = cells[(cells["method"] == "gcdt") & cells["paper_success"].notna()]
    rows = []
    for c in cells.itertuples():
        own = runs[
            runs["sections"].apply(lambda s: "table1" in s)
            & (runs["method"] == "gcdt")
            & (runs["task"] == c.task)
            & (runs["reward"] == c.reward)
        ]
        data = [t["dataset"] for t in own["training"] if t.get("dataset")]
        success_gap = c.success_mean - c.paper_success
        return_gap = (c.return_mean - c.paper_return) / abs(c.paper_return)
        rows.append(
            {
                "reward": c.reward,
                "task": c.task,
                "seeds": int(c.seeds),
                "success_mean": c.success_mean,
                "paper_success": c.paper_success,
                "success_gap": success_gap,
                "return_mean": c.return_mean,
                "paper_return": c.paper_return,
                "return_gap": return_gap,  # a share of the paper's return; > 0 is better
                "data_success": _mean(d.get("success_rate") for d in data) * 100,
                "data_return": _mean(d.get(f"mean_return_{c.reward}") for d in data),
                "success_met": bool(abs(success_gap) <= SUCCESS_POINTS),
                "return_met": bool(abs(return_gap) <= RETURN_SHARE),
            }
        )
    return pd.DataFrame(rows)


def _mean(values) -> float:
    found = [v for v in values if v is not None]
    return float(np.mean(found)) if found else np.nan


def fidelity_markdown(table: pd.DataFrame) -> str:
    """`fidelity_table` as Markdown, a missed target in bold, and a last line that counts."""
    lines = [
        "| reward | task | seeds | success % (paper) | gap (pts) | return (paper) | return gap "
        "| the data's own success % / return |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in table.itertuples():
        gap = f"{r.success_gap:+.1f}" if r.success_met else f"**{r.success_gap:+.1f}**"
        off = f"{round(r.return_gap * 100):+d} %"  # (rounded first: no "-0 %")
        off = off if r.return_met else f"**{off}**"
        data = "–" if np.isnan(r.data_success) else f"{r.data_success:.1f} / {r.data_return:.2f}"
        lines.append(
            f"| {r.reward} | {TASK_NAMES[r.task]} | {r.seeds} | {r.success_mean:.1f} "
            f"({r.paper_success:.1f}) | {gap} | {r.return_mean:.2f} "
            f"({r.paper_return:.2f}) | {off} | {data} |"
        )
    met = int((table["success_met"] & table["return_met"]).sum())
    lines.append(f"| **both targets met** | | | | | | | {met} of {len(table)} cells |")
    return "\n".join(lines)
