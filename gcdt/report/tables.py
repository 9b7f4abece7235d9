"""Tables from `results/<profile>/runs/` alone: Table 1 (RQ1-RQ3) and the DT ablation.

Each cell is the mean over seeds with its standard deviation and a 95 % confidence interval
of that mean (bootstrap over seeds; with one seed, over its evaluation episodes), and
Table 1 puts the paper's values beside ours. Written as CSV, Markdown and LaTeX (booktabs,
laid out like the paper's table: rewards as blocks, methods as rows, tasks as columns).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import stats

from gcdt import paper
from gcdt.baselines.publish import AGENTS_DIR, agent_dirs, read_agent
from gcdt.baselines.tqc_her import EVAL_CSV, RUN_JSON
from gcdt.errors import GcdtError
from gcdt.experiments.costs import CostModel
from gcdt.experiments.grid import build_grid
from gcdt.experiments.profiles import Profile
from gcdt.experiments.store import RunStore
from gcdt.experiments.sweep import plan
from gcdt.paths import results_dir

TASK_NAMES = {"reach": "Reach", "push": "Push", "pick_and_place": "PickAndPlace"}
METHOD_NAMES = {
    "gcdt": "GC-DT",
    "bc": "BC",
    "tqc": "TQC+HER",
    "dt": "DT (no goal)",
    "dt-desired": "DT (desired goal)",
}
#: Table 1 of the paper: (return, success %) per reward, method, task. Its "DT" is GC-DT.
PAPER_TABLE1 = {
    (reward, method): dict(zip(("reach", "push", "pick_and_place"), cells, strict=True))
    for reward, method, cells in (
        ("dense", "gcdt", ((-0.21, 100.0), (-0.95, 99.5), (-1.30, 98.9))),
        ("dense", "bc", ((-0.21, 100.0), (-1.20, 95.9), (-1.35, 97.9))),
        ("dense", "tqc", ((-0.21, 100.0), (-1.04, 98.7), (-1.35, 98.7))),
        ("sparse", "gcdt", ((-1.72, 100.0), (-8.26, 95.0), (-7.63, 97.8))),
        ("sparse", "bc", ((-1.76, 100.0), (-8.18, 94.6), (-9.01, 94.9))),
        ("sparse", "tqc", ((-1.82, 100.0), (-4.54, 99.5), (-16.96, 77.0))),
    )
}
BOOTSTRAP_SAMPLES = 10_000


#: The key of a published agent's row in `load_runs`: a Table 1 cell, not a run of the grid.
AGENT_KEY = "agent:"


def load_runs(
    profile: Profile, runs_dir: str | Path | None = None, agents: bool = True
) -> pd.DataFrame:
    """One row per finished run of `profile`'s grid: its spec, sections, metrics, and what its
    training recorded (`training`: curves, dataset summary, model config). `runs_dir` defaults
    to `results/<profile>/runs/` under `gcdt.paths.outputs_root()`. With `agents`, a profile
    with `tqc_agents` also gets its published agents' rows (`agent_rows`, keys starting
    `AGENT_KEY`); a profile with no finished grid run is refused either way."""
    store = RunStore(Path(runs_dir) if runs_dir else results_dir(profile.name) / "runs")
    rows = []
    for entry in build_grid(profile):
        stored = store.read(entry.spec.key())
        if stored.state != "done":
            continue
        spec, result = entry.spec, stored.result
        metrics = result["metrics"]
        rows.append(
            {
                "key": spec.key(),
                "sections": entry.sections,
                "method": spec.method,
                "task": spec.task,
                "reward": spec.reward,
                "seed": spec.seed,
                "train_steps": spec.train_steps,
                "size": spec.data.size if spec.data else None,
                "expert_ratio": spec.data.expert_ratio if spec.data else None,
                "target_return": spec.target_return,
                "eval_region": spec.eval_region,
                "train_region": spec.data.goal_region if spec.data else None,
                "success_rate": metrics["success_rate"],
                "mean_return": metrics["mean_return"],
                "episodes": metrics["episodes"],
                "std_return": _pooled_std(result.get("evaluations", [])),
                "evaluations": result.get("evaluations", []),
                "training": result.get("training", {}),
                "execution": result.get("execution", {}),  # when, where, how long
            }
        )
    if not rows:
        others = len(list(store.root.glob("*.json"))) if store.root.is_dir() else 0
        earlier = f" (its {others} result files are of an earlier grid)" if others else ""
        raise GcdtError(
            f"no finished runs of profile {profile.name!r} in {store.root}{earlier}: run "
            f"`gcdt sweep --profile {profile.name}` (or `make reproduce PROFILE={profile.name}`)"
        )
    if agents and profile.tqc_agents:
        rows += agent_rows(profile)
    return pd.DataFrame(rows)


def agent_rows(profile: Profile, agents_dir: str | Path = AGENTS_DIR) -> list[dict]:
    """Table 1's TQC+HER cells of a profile with `tqc_agents`: each published agent of its
    Table 1 tasks and rewards, every seed, of the profile's `agent_steps`, as a run row whose
    metrics are the agent's held-out evaluation (`gcdt.baselines.publish`). Agents not
    published yet, or of another number of steps, are left out: a cell is empty, or the mean
    over the seeds that are there."""
    rows, steps = [], profile.agent_steps
    for task in profile.table1.tasks:
        for reward in profile.table1.rewards:
            for folder in agent_dirs(task, reward, agents_dir):
                record = read_agent(folder) or {}
                if record and (record["task"], record["reward"]) != (task, reward):
                    raise GcdtError(
                        f"{folder} holds a {record['task']}/{record['reward']} agent, not "
                        f"{task}/{reward}: publish it again into its own folder"
                    )
                if "published" in record and steps in (None, record["env_steps"]):
                    rows.append(_agent_row(folder, record))
    return rows


def _agent_row(folder: Path, record: dict) -> dict:
    """A published agent's held-out evaluation as a run row of its Table 1 TQC+HER cell."""
    held_out = record["published"]["held_out"]
    return {
        "key": f"{AGENT_KEY}{folder.name}",
        "sections": ("table1",),
        "method": "tqc",
        "task": record["task"],
        "reward": record["reward"],
        "seed": record["seed"],
        "train_steps": None,
        "size": None,
        "expert_ratio": None,
        "target_return": paper.TARGET_RETURN,
        "eval_region": None,
        "train_region": None,
        "success_rate": held_out["success_rate"],
        "mean_return": held_out["mean_return"],
        "episodes": held_out["episodes"],
        "std_return": held_out["std_return"],
        "evaluations": [held_out],
        "training": {"curve": record["curve"], "env_steps": record["env_steps"]},
        "execution": {"agent": folder.name, "core_hours": record.get("core_hours")},
    }


def load_agent_curves(agents_dir: str | Path = AGENTS_DIR) -> pd.DataFrame:
    """The learning curves of the published TQC+HER agents: one row per evaluation point
    (task, reward, seed, env_steps, success_rate, mean_return, episodes, agent), read from
    each agent's `run.json` (what it is) and `eval.csv` (its held-out curve)."""
    frames = []
    for run in sorted(Path(agents_dir).glob(f"tqc_*/{RUN_JSON}")):
        record = read_agent(run.parent)
        curve = pd.read_csv(run.parent / EVAL_CSV)
        frames.append(
            curve.assign(
                task=record["task"],
                reward=record["reward"],
                seed=record["seed"],
                agent=run.parent.name,
            )
        )
    columns = ["task", "reward", "seed", "env_steps", "success_rate", "mean_return", "episodes"]
    if not frames:
        return pd.DataFrame(columns=[*columns, "agent"])
    return pd.concat(frames, ignore_index=True)[[*columns, "agent"]]


def _pooled_std(evaluations: list[dict]) -> float:
    """Standard deviation of the episode returns over all of a run's evaluation seeds."""
    done = [e for e in evaluations if e["episodes"] and e["mean_return"] is not None]
    n = sum(e["episodes"] for e in done)
    if n < 2:
        return float("nan")
    mean = sum(e["episodes"] * e["mean_return"] for e in done) / n
    square = sum(e["episodes"] * (e["std_return"] ** 2 + e["mean_return"] ** 2) for e in done)
    return float(np.sqrt(max(square / n - mean**2, 0.0)))


def bootstrap_ci(values: np.ndarray, seed: int = 0) -> tuple[float, float]:
    """95 % percentile-bootstrap interval of the mean of `values` (seeds), by scipy."""
    values = np.asarray(values, dtype=np.float64)
    if len(values) < 2 or np.all(values == values[0]):  # no spread: nothing to resample
        return float(values[0]), float(values[0])
    result = stats.bootstrap(
        (values,),
        np.mean,
        n_resamples=BOOTSTRAP_SAMPLES,
        confidence_level=0.95,
        method="percentile",
        rng=np.random.default_rng(seed),
    )
    return float(result.confidence_interval.low), float(result.confidence_interval.high)


def wilson_ci(rate: float, n: int) -> tuple[float, float]:
    """95 % Wilson score interval of a success rate measured on `n` episodes, by scipy."""
    if not n:
        return float("nan"), float("nan")
    interval = stats.binomtest(round(rate * n), n).proportion_ci(0.95, method="wilson")
    return float(interval.low), float(interval.high)


def _episodes(group: pd.DataFrame, metric: str) -> tuple[float, float, int]:
    """(mean, standard deviation over episodes, episodes) of the metric of a cell's one run
    (its first with a value): a success rate's episodes are 0 or 1. The deviation is the
    evaluation's own (ddof 0; NaN when the run stored none)."""
    run = group[group[metric].notna()].iloc[0]
    n = int(run["episodes"])
    if metric == "success_rate":
        rate = float(run["success_rate"])
        return rate, float(np.sqrt(rate * (1 - rate))), n
    return float(run["mean_return"]), float(run["std_return"]), n


def _interval(group: pd.DataFrame, metric: str, scale: float) -> tuple[float, float]:
    """95 % interval of a cell's mean: over seeds (bootstrap) when it has several; with one
    seed, over that run's evaluation episodes (Wilson for success, normal for return), since
    a single value has no spread of its own."""
    values = group[metric].dropna().to_numpy(dtype=np.float64)
    if not len(values):
        return np.nan, np.nan
    if len(values) > 1:
        return bootstrap_ci(values * scale)
    mean, std, n = _episodes(group, metric)
    if metric == "success_rate":
        low, high = wilson_ci(mean, n)
    else:
        half = 1.96 * std / np.sqrt(max(n, 1))
        low, high = mean - half, mean + half
    return low * scale, high * scale


@dataclass(frozen=True)
class Sample:
    """What a cell's mean is a mean of, summarised for comparing two runs of the cell: its
    seeds' values when it has several; with one seed, that run's evaluation episodes (the
    same choice as the cell's interval)."""

    mean: float
    std: float  # sample standard deviation (ddof 1); NaN when unknown
    n: int
    over: str  # "seeds" or "episodes"


def cell_sample(group: pd.DataFrame, metric: str, scale: float) -> Sample | None:
    """The `Sample` of a cell's `metric` (times `scale`); None when no run has a value."""
    values = group[metric].dropna().to_numpy(dtype=np.float64) * scale
    if not len(values):
        return None
    if len(values) > 1:
        return Sample(float(values.mean()), float(values.std(ddof=1)), len(values), "seeds")
    mean, std, n = _episodes(group, metric)
    std = std * np.sqrt(n / (n - 1)) if n > 1 else np.nan  # the evaluation's ddof 0 to ddof 1
    return Sample(mean * scale, std * scale, n, "episodes")


#: What `aggregate` gives per group, beside the group's keys.
_STATS = ("mean", "std", "ci_low", "ci_high")
AGGREGATES = (*(f"{m}_{s}" for m in ("return", "success") for s in _STATS), "seeds")
#: What `aggregate` adds with `samples`: each metric's `Sample`.
SAMPLES = ("return_sample", "success_sample")


def aggregate(runs: pd.DataFrame, by: list[str], samples: bool = False) -> pd.DataFrame:
    """Per group of `by`: mean, std and 95 % interval of return and success (%), and seeds
    (no rows, with those columns, when `runs` has none); with `samples`, also each metric's
    `Sample` (columns `SAMPLES`), for comparing two runs of the same cells."""
    if runs.empty:
        return pd.DataFrame(columns=[*by, *AGGREGATES, *(SAMPLES if samples else ())])
    rows = []
    for keys, group in runs.groupby(by, sort=False):
        row = dict(zip(by, keys, strict=True))
        for metric, scale in (("mean_return", 1.0), ("success_rate", 100.0)):
            values = group[metric].dropna().to_numpy(dtype=np.float64) * scale
            name = "return" if metric == "mean_return" else "success"
            low, high = _interval(group, metric, scale)
            row |= {
                f"{name}_mean": values.mean() if len(values) else np.nan,
                f"{name}_std": values.std(ddof=1) if len(values) > 1 else 0.0,
                f"{name}_ci_low": low,
                f"{name}_ci_high": high,
            }
            if samples:
                row[f"{name}_sample"] = cell_sample(group, metric, scale)
        row["seeds"] = len(group)
        rows.append(row)
    return pd.DataFrame(rows)


#: Fig. 3 and Fig. 4: the grid section each is drawn from and the quantity on its x axis.
CURVES = {"fig3_dataset_size": ("rq4", "size"), "fig4_expert_ratio": ("rq5", "expert_ratio")}


def curve_table(runs: pd.DataFrame, section: str, x: str, samples: bool = False) -> pd.DataFrame:
    """GC-DT per reward, task and `x` over the runs of `section` (Fig. 3: "rq4", "size";
    Fig. 4: "rq5", "expert_ratio"), as `aggregate` gives it (with `samples`, theirs too);
    empty without such runs."""
    sel = runs[runs["sections"].apply(lambda s: section in s) & (runs["method"] == "gcdt")]
    if sel.empty:
        return pd.DataFrame()
    table = aggregate(sel, ["reward", "task", x], samples)
    order = {task: i for i, task in enumerate(TASK_NAMES)}
    keys = [table["reward"], table["task"].map(order), table[x]]
    return table.iloc[np.lexsort(keys[::-1])].reset_index(drop=True)


def curve_markdown(table: pd.DataFrame, x: str) -> str:
    """`curve_table` as Markdown: one row per reward and task, one column per value of `x`,
    cells 'success % [95 % interval over seeds]'; a sentence when there are none."""
    if table.empty:
        return "*No runs of this figure in this profile.*"
    values = sorted(table[x].unique())
    label = {"size": lambda v: f"{int(v):,}", "expert_ratio": lambda v: f"{100 * v:.0f} %"}[x]
    lines = [
        "| reward | task | " + " | ".join(label(v) for v in values) + " |",
        "|---|---|" + "---|" * len(values),
    ]
    for (reward, task), group in table.groupby(["reward", "task"], sort=False):
        cells = {row[x]: row for _, row in group.iterrows()}
        lines.append(
            f"| {reward} | {TASK_NAMES[task]} | "
            + " | ".join(
                f"{c['success_mean']:.1f} [{c['success_ci_low']:.1f}, {c['success_ci_high']:.1f}]"
                if (c := cells.get(v)) is not None
                else "--"
                for v in values
            )
            + " |"
        )
    return "\n".join(lines)


def datasets_table(runs: pd.DataFrame) -> pd.DataFrame:
    """The distinct training datasets of the runs (size, expert share, and the summary each
    run stored: episodes, mean length, success rate, mean returns), one row each."""
    rows = {
        (r.task, r.size, r.expert_ratio): {
            "task": r.task,
            "size": r.size,
            "expert share": r.expert_ratio,
            **{k: v for k, v in r.training["dataset"].items() if k not in ("source", "policy")},
        }
        for r in runs.itertuples()
        if r.size is not None and r.training.get("dataset")
    }
    return pd.DataFrame([rows[k] for k in sorted(rows)])


def table1(runs: pd.DataFrame, samples: bool = False) -> pd.DataFrame:
    """Table 1: per reward, method and task, our mean ± std (and CI) beside the paper's (with
    `samples`, `aggregate`'s samples too)."""
    sel = runs[runs["sections"].apply(lambda s: "table1" in s)]
    table = aggregate(sel, ["reward", "method", "task"], samples)
    paper = [
        PAPER_TABLE1.get((r.reward, r.method), {}).get(r.task, (np.nan, np.nan))
        for r in table.itertuples()
    ]
    table["paper_return"] = [p[0] for p in paper]
    table["paper_success"] = [p[1] for p in paper]
    return _ordered(table, ["dense", "sparse"], ["gcdt", "bc", "tqc"])


def ablation_table(runs: pd.DataFrame, samples: bool = False) -> pd.DataFrame:
    """GC-DT against DT without goals and DT with the desired goal only, same data (with
    `samples`, `aggregate`'s samples too)."""
    full = runs[runs["sections"].apply(lambda s: "ablation" in s or "table1" in s)]
    full = full[full["method"].isin(["gcdt", "dt-desired", "dt"])]
    scoped = full.merge(
        runs[runs["sections"].apply(lambda s: "ablation" in s)][
            ["task", "reward"]
        ].drop_duplicates(),
        on=["task", "reward"],
    )
    return _ordered(
        aggregate(scoped, ["reward", "method", "task"], samples),
        ["dense", "sparse"],
        ["gcdt", "dt-desired", "dt"],
    )


def _ordered(table: pd.DataFrame, rewards: list[str], methods: list[str]) -> pd.DataFrame:
    order = {
        "reward": {r: i for i, r in enumerate(rewards)},
        "method": {m: i for i, m in enumerate(methods)},
        "task": {t: i for i, t in enumerate(TASK_NAMES)},
    }
    return table.sort_values(list(order), key=lambda c: c.map(order[c.name])).reset_index(drop=True)


def _cell(row: pd.Series, paper: bool, pm: str = " ± ", interval: bool = True) -> str:
    """'return / success' (mean ± std over seeds, and with `interval` the success rate's 95 %
    interval over seeds in brackets; one seed has no spread to show)."""
    if row["seeds"] > 1:
        ours = (
            f"{row['return_mean']:.2f}{pm}{row['return_std']:.2f} / "
            f"{row['success_mean']:.1f}{pm}{row['success_std']:.1f}"
        )
        if interval:
            ours += f" [{row['success_ci_low']:.1f}, {row['success_ci_high']:.1f}]"
    else:
        ours = f"{row['return_mean']:.2f} / {row['success_mean']:.1f}"
    if paper and not np.isnan(row.get("paper_return", np.nan)):
        ours += f" (paper {row['paper_return']:.2f} / {row['paper_success']:.1f})"
    return ours


def to_markdown(table: pd.DataFrame, paper: bool = True) -> str:
    """Rewards as blocks, methods as rows, tasks as columns: 'return / success %' cells."""
    tasks = [t for t in TASK_NAMES if t in set(table["task"])]
    lines = [
        "| Method | " + " | ".join(TASK_NAMES[t] for t in tasks) + " |",
        "|---|" + "---|" * len(tasks),
    ]
    for reward, block in table.groupby("reward", sort=False):
        lines.append(f"| *{reward.capitalize()} reward* |" + " |" * len(tasks))
        for method, rows in block.groupby("method", sort=False):
            cells = {r["task"]: _cell(r, paper) for _, r in rows.iterrows()}
            lines.append(
                f"| {METHOD_NAMES[method]} | " + " | ".join(cells.get(t, "–") for t in tasks) + " |"
            )
    return "\n".join(lines)


def to_latex(table: pd.DataFrame, caption: str, label: str) -> str:
    """A booktabs table laid out like the paper's Table 1 (return / success %, mean ± std)."""
    tasks = [t for t in TASK_NAMES if t in set(table["task"])]
    cols = len(tasks) + 2
    out = [
        r"\begin{table*}[tb]",
        rf"\caption{{{caption}}}",
        rf"\label{{{label}}}",
        r"\centering",
        r"\scriptsize",
        r"\setlength{\tabcolsep}{3pt}",
        r"\begin{tabular}{l" + "c" * (cols - 1) + "}",
        r"\toprule",
        r"\textbf{Method} & \textbf{Metric} & "
        + " & ".join(rf"\textbf{{{TASK_NAMES[t]}}}" for t in tasks)
        + r" \\",
    ]
    for reward, block in table.groupby("reward", sort=False):
        out += [
            r"\midrule",
            rf"\multicolumn{{{cols}}}{{c}}{{\textit{{{reward.capitalize()} "
            r"Reward}} \\",
            r"\midrule",
        ]
        for method, rows in block.groupby("method", sort=False):
            cells = {
                r["task"]: _cell(r, False, pm=" $\\pm$ ", interval=False)
                for _, r in rows.iterrows()
            }
            out.append(
                f"{METHOD_NAMES[method]} & Ret / Succ & "
                + " & ".join(cells.get(t, "--") for t in tasks)
                + r" \\"
            )
    out += [r"\bottomrule", r"\end{tabular}", r"\end{table*}"]
    return "\n".join(out) + "\n"


def _paper_trend(section: str, task: str) -> tuple[bool, str]:
    """(holds in the paper, claim) for RQ4 / RQ5, from Section V and Fig. 3-4: success on the
    smallest subset is below the full data's for Push and PickAndPlace and "invariant to size"
    for Reach; it falls with the expert share and "drops sharply" at 0 %."""
    if section == "rq4":
        return task != "reach", "less success on the smallest subset than on all data"
    return True, "less success at 0 % expert than at 100 %"


@dataclass(frozen=True)
class Floor:
    """A claim that GC-DT's success stays above `success` % at `expert_ratio` expert data."""

    expert_ratio: float
    success: float
    tasks: tuple[str, ...]


#: The paper's RQ5 claim for its complex tasks (Section V): success stays above 80 % with only
#: 25 % expert data.
RQ5_FLOOR = Floor(expert_ratio=0.25, success=80.0, tasks=("push", "pick_and_place"))

#: Success-rate differences below this many points count as equal: the paper's ties are
#: exact (100 / 100), and one of our ~200 evaluation episodes is already half a point.
EQUAL_POINTS = 1.0


def _sign(diff: float) -> str:
    return "equal" if abs(diff) < EQUAL_POINTS else "higher" if diff > 0 else "lower"


def directions(runs: pd.DataFrame, profile: Profile | None = None) -> pd.DataFrame:
    """Every comparison the paper's results make, with the paper's answer and ours.

    Table 1: GC-DT against BC and TQC+HER, per task and reward (success rate, points).
    RQ4 / RQ5: whether GC-DT's success is lower at the smallest subset than on all the data,
    and at 0 % expert than at 100 %. `agrees` is whether both point the same way (differences
    under EQUAL_POINTS count as equal); with one seed and a short evaluation, a difference of
    one episode can be several points. With `profile`, a curve missing any of its subset
    sizes or expert shares (a grid still running) is left out rather than read from its ends.
    """
    rows = []
    table = table1(runs).set_index(["reward", "method", "task"])
    for (reward, method, task), row in table.iterrows():
        if method == "gcdt" or (reward, "gcdt", task) not in table.index:
            continue
        ours = table.loc[(reward, "gcdt", task)]
        paper = ours["paper_success"] - row["paper_success"]
        diff = ours["success_mean"] - row["success_mean"]
        rows.append(
            {
                "comparison": f"GC-DT vs {METHOD_NAMES[method]}, {TASK_NAMES[task]} {reward}",
                "paper": f"{_sign(paper)} ({paper:+.1f} pts)",
                "ours": f"{_sign(diff)} ({diff:+.1f} pts)",
                "agrees": _sign(paper) == _sign(diff),
            }
        )
    for (section, x), low_label, high_label in zip(
        CURVES.values(), ("smallest", "0 %"), ("all", "100 %"), strict=True
    ):
        curve = curve_table(runs, section, x)
        if curve.empty:
            continue
        planned = {"rq4": profile.rq4_sizes, "rq5": profile.rq5_ratios}[section] if profile else ()
        for (reward, task), cell in curve.groupby(["reward", "task"], sort=False):
            means = cell.set_index(x)["success_mean"]  # sorted by x
            # The trend needs the curve's ends and every planned point; RQ5's floor, only its
            # share (a grid still running checks the disputed claim first).
            ends = section != "rq5" or {0.0, 1.0} <= set(means.index)
            if ends and set(planned) <= set(means.index):
                diff = means.iloc[0] - means.iloc[-1]
                lower, claim = _paper_trend(section, task)
                ours_lower = diff < 0
                values = f"{low_label} {means.iloc[0]:.1f} % vs {high_label} {means.iloc[-1]:.1f} %"
                rows.append(
                    {
                        "comparison": f"{section.upper()}, {TASK_NAMES[task]} {reward}: {claim}",
                        "paper": "yes" if lower else "no (invariant)",
                        "ours": f"{'yes' if ours_lower else 'no'} ({values})",
                        "agrees": lower == ours_lower,
                    }
                )
            share, floor = RQ5_FLOOR.expert_ratio, RQ5_FLOOR.success
            if section == "rq5" and task in RQ5_FLOOR.tasks and share in means.index:
                above = bool(means[share] > floor)
                rows.append(
                    {
                        "comparison": f"RQ5, {TASK_NAMES[task]} {reward}: above {floor:.0f} % "
                        f"success at {100 * share:.0f} % expert",
                        "paper": "yes",
                        "ours": f"{'yes' if above else 'no'} ({means[share]:.1f} %)",
                        "agrees": above,
                    }
                )
    return pd.DataFrame(rows, columns=["comparison", "paper", "ours", "agrees"])


def directions_markdown(runs: pd.DataFrame) -> str:
    table = directions(runs)
    lines = ["| comparison | paper | ours | same direction |", "|---|---|---|---|"]
    lines += [
        f"| {r.comparison} | {r.paper} | {r.ours} | {'yes' if r.agrees else '**no**'} |"
        for r in table.itertuples()
    ]
    return "\n".join(lines)


#: What makes a grid cell, beside its seed: runs that differ only in their seed share one.
CELL = ["method", "task", "reward", "size", "expert_ratio", "train_steps", "target_return",
        "eval_region", "train_region"]  # fmt: skip


def progress(runs: pd.DataFrame, profile: Profile) -> tuple[int, int]:
    """(finished, planned) runs of `profile`'s grid, `runs` being its `load_runs` (whose
    published agents' rows are no runs of the grid)."""
    return int((~runs["key"].str.startswith(AGENT_KEY)).sum()), len(build_grid(profile))


def sections_left(profile: Profile) -> pd.DataFrame:
    """Per section of `profile`'s grid, in its sweep's order: runs finished, runs planned, and
    the dry run's estimate of the hours the rest take (`gcdt sweep --dry-run`'s cost model,
    measured from the published runs; collections, this CPU's speed and the checkpoints
    here excluded: those depend on the machine, the report does not). Each run counts in the
    first of its sections, as the dry run counts it."""
    costs = CostModel.measured(profile.name, this_machine=False)
    store = RunStore(results_dir(profile.name) / "runs")
    planned, _ = plan(profile, store, costs=costs, checkpoints=False)
    rows: dict[str, dict] = {}
    for run in planned:
        row = rows.setdefault(
            run.entry.sections[0],
            {"section": run.entry.sections[0], "finished": 0, "planned": 0, "hours_left": 0.0},
        )
        row["planned"] += 1
        if run.state == "done":
            row["finished"] += 1
        else:
            row["hours_left"] += run.estimate_seconds / 3600
    return pd.DataFrame(
        list(rows.values()), columns=["section", "finished", "planned", "hours_left"]
    )


def sections_left_markdown(table: pd.DataFrame) -> str:
    """`sections_left` as Markdown: a finished section's estimate is '--'."""
    lines = [
        "| section | runs finished | of | the rest, estimated |",
        "|---|---|---|---|",
    ]
    for r in table.itertuples(index=False):
        rest = "--" if r.finished == r.planned else f"about {r.hours_left:.1f} h of work"
        lines.append(f"| {r.section} | {r.finished} | {r.planned} | {rest} |")
    return "\n".join(lines)


def complete_cells(runs: pd.DataFrame, profile: Profile) -> pd.DataFrame:
    """The rows of `runs` whose cell has every one of `profile`'s seeds (a published agent's
    row stands alone): a grid still running publishes no mean of fewer seeds than planned."""
    grid = ~runs["key"].str.startswith(AGENT_KEY)
    seeds = runs[grid].groupby(CELL, dropna=False)["seed"].transform("nunique")
    whole = pd.Series(True, index=runs.index)
    whole[grid] = seeds >= len(profile.seeds)
    return runs[whole]


def directions_across(profiles: list[Profile]) -> pd.DataFrame:
    """`directions` of every profile in `profiles` with published runs, side by side: one row
    per comparison, the paper's answer, then per profile ours, or None where that profile
    does not make the comparison (or has not finished every seed of its cells). So a reader
    sees which disagreements go away at scale."""
    tables, partial = {}, {}
    for profile in profiles:
        try:
            finished = load_runs(profile)
        except GcdtError:
            continue  # nothing published for this profile yet
        runs = complete_cells(finished, profile)
        table = directions(runs, profile) if not runs.empty else pd.DataFrame()
        if not table.empty:  # runs, but none of the comparisons (a section alone)
            tables[profile.name] = table.set_index("comparison")
            done, planned = progress(finished, profile)
            if done < planned:  # a grid still running: the header says so
                partial[profile.name] = (done, planned)
    rows: dict[str, dict] = {}
    for name, table in tables.items():
        for comparison, row in table.iterrows():
            cell = rows.setdefault(comparison, {"comparison": comparison, "paper": row["paper"]})
            cell[name] = (row["ours"], bool(row["agrees"]))
    out = pd.DataFrame(list(rows.values()), columns=["comparison", "paper", *tables])
    out.attrs["partial"] = partial  # profile -> (finished runs, planned runs)
    return out


def table1_across(profiles: list[Profile]) -> pd.DataFrame:
    """Table 1's cells in every profile of `profiles` with published runs, beside the paper's:
    one row per reward, method and task, per profile its "return / success %" (cells with
    every seed only), so a reader sees which numbers move towards the paper's with scale."""
    cells: dict[tuple, dict] = {}
    names: list[str] = []
    for profile in profiles:
        try:
            runs = complete_cells(load_runs(profile), profile)
        except GcdtError:
            continue  # nothing published for this profile yet
        table = table1(runs) if not runs.empty else pd.DataFrame()
        if table.empty:
            continue
        names.append(profile.name)
        for _, row in table.iterrows():
            cell = cells.setdefault(
                (row["reward"], row["method"], row["task"]),
                {"reward": row["reward"], "method": row["method"], "task": row["task"]},
            )
            cell[profile.name] = f"{row['return_mean']:.2f} / {row['success_mean']:.1f}"
            if not np.isnan(row["paper_return"]):
                cell["paper"] = f"{row['paper_return']:.2f} / {row['paper_success']:.1f}"
    columns = ["reward", "method", "task", *names, "paper"]
    out = pd.DataFrame(list(cells.values()), columns=columns)
    return _ordered(out, ["dense", "sparse"], ["gcdt", "bc", "tqc"]) if len(out) else out


def table1_across_markdown(profiles: list[Profile]) -> str:
    """`table1_across` as Markdown ("--": the profile has no finished cell there)."""
    table = table1_across(profiles)
    names = list(table.columns[3:-1])
    if not names:
        return "*No profile has published a Table 1 cell with every seed.*"
    lines = [
        "| reward | method | task | " + " | ".join(f"`{n}`" for n in names) + " | paper |",
        "|---|---|---|" + "---|" * (len(names) + 1),
    ]
    for row in table.itertuples(index=False):
        values = ["--" if not isinstance(v, str) else v for v in row[3:]]
        lines.append(
            f"| {row.reward} | {METHOD_NAMES[row.method]} | {TASK_NAMES[row.task]} | "
            + " | ".join(values)
            + " |"
        )
    return "\n".join(lines)


def directions_across_markdown(profiles: list[Profile]) -> str:
    """`directions_across` as Markdown, a disagreement in bold, and each profile's count."""
    table = directions_across(profiles)
    names = list(table.columns[2:])
    if not names:
        return "*No profile has published the runs these comparisons need.*"
    partial = table.attrs.get("partial", {})
    heads = [
        f"`{n}`" + (f" ({partial[n][0]} of {partial[n][1]} runs)" if n in partial else "")
        for n in names
    ]
    lines = [
        "| comparison | paper | " + " | ".join(heads) + " |",
        "|---|---|" + "---|" * len(names),
    ]
    for row in table.itertuples(index=False):
        cells = [
            "--" if not isinstance(c, tuple) else c[0] if c[1] else f"**{c[0]}**" for c in row[2:]
        ]
        lines.append(f"| {row.comparison} | {row.paper} | " + " | ".join(cells) + " |")
    made = [[c for c in table[n] if isinstance(c, tuple)] for n in names]
    counts = [f"{sum(a for _, a in cells)} of {len(cells)}" for cells in made]
    lines.append("| **same direction as the paper** | | " + " | ".join(counts) + " |")
    return "\n".join(lines)
