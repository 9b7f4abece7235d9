"""Table 1's TQC+HER cells from the published agents (`results/experts/tqc_*/`) alone.

One row per task and reward of the paper's TQC+HER row: the agent's held-out success rate
(`gcdt tqc publish`'s measurement; 95 % interval: Wilson over its episodes with one seed,
bootstrap over seeds with several) and return, its online env steps and seeds, the paper's
values and budget, and the agent's success at smaller budgets read from its learning curve
(the periodic evaluations of training, on their own episodes). A cell without a published
agent is a "not yet published" row, and an agent published without a held-out measurement
(before `gcdt tqc publish`) shows its curve only. Written by `gcdt report` to
`results/experts/table1_tqc.{md,csv}`. The Markdown goes on with the runs in progress whose
snapshots are committed (`in_progress_table`): each one's curve so far beside the published
agent's at the same steps, the comparison a candidate config is judged by.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from gcdt.baselines.publish import AGENTS_DIR, HELD_OUT_SEED, SNAPSHOTS_DIR, read_agent
from gcdt.baselines.tqc_checkpoint import CHECKPOINT_FILE, read_header
from gcdt.baselines.tqc_her import EVAL_CSV, RUN_JSON, load_tqc_config
from gcdt.errors import GcdtError
from gcdt.report.tables import PAPER_TABLE1, TASK_NAMES, aggregate, load_agent_curves

#: The budgets (env steps) at which the learning curves are read, where they reach them.
CURVE_BUDGETS = (100_000, 250_000, 500_000, 1_000_000)
#: A row's state: measured held out, published before held-out measurements, or missing.
PUBLISHED, NO_HELD_OUT, NOT_PUBLISHED = "published", "no held-out record", "not yet published"
#: The table's columns (success in %, the interval's bounds too).
COLUMNS = [
    "task",
    "reward",
    "status",
    "success",
    "success_ci_low",
    "success_ci_high",
    "return",
    "held_out_episodes",
    "env_steps",
    "seeds",
    "paper_success",
    "paper_return",
    "paper_steps",
    *(f"curve_success_{budget}" for budget in CURVE_BUDGETS),
]


def load_agents(agents_dir: str | Path = AGENTS_DIR) -> pd.DataFrame:
    """One row per published agent: task, reward, seed, agent, env_steps, n_envs and its
    held-out measurement (success_rate, mean_return, std_return, episodes; NaN without one)."""
    rows = []
    measurement = ("success_rate", "mean_return", "std_return", "episodes")
    for path in sorted(Path(agents_dir).glob(f"tqc_*/{RUN_JSON}")):
        record = read_agent(path.parent)
        held_out = record.get("published", {}).get("held_out", {})
        rows.append(
            {
                "task": record["task"],
                "reward": record["reward"],
                "seed": record["seed"],
                "agent": path.parent.name,
                "env_steps": record["env_steps"],
                "n_envs": record["config"]["n_envs"],
                **{key: held_out.get(key, np.nan) for key in measurement},
            }
        )
    columns = ["task", "reward", "seed", "agent", "env_steps", "n_envs", *measurement]
    return pd.DataFrame(rows, columns=columns)


def _curve_success(curve: pd.DataFrame, budget: int, n_envs: int) -> float:
    """Success (%) of the evaluation made at `budget` steps (one loop iteration of `n_envs`
    steps may carry it past), NaN where the curve has none."""
    at = curve[(curve["env_steps"] >= budget) & (curve["env_steps"] < budget + n_envs)]
    return 100 * float(at["success_rate"].iloc[0]) if len(at) else np.nan


def agents_table(agents_dir: str | Path = AGENTS_DIR) -> pd.DataFrame:
    """Every TQC+HER cell of Table 1 (task-major), ours beside the paper's (see the module)."""
    agents, curves = load_agents(agents_dir), load_agent_curves(agents_dir)
    rows = []
    for task in TASK_NAMES:
        for reward in ("dense", "sparse"):
            paper_return, paper_success = PAPER_TABLE1[(reward, "tqc")][task]
            row = {
                "task": task,
                "reward": reward,
                "status": NOT_PUBLISHED,
                "seeds": 0,
                "paper_success": paper_success,
                "paper_return": paper_return,
                "paper_steps": load_tqc_config("paper", task).steps,
            }
            cell = agents[(agents["task"] == task) & (agents["reward"] == reward)]
            if len(cell):
                row |= _ours(cell, curves)
            rows.append(row)
    counts = {"held_out_episodes": "Int64", "env_steps": "Int64"}  # blank where unpublished
    return pd.DataFrame(rows, columns=COLUMNS).astype(counts)


def _ours(cell: pd.DataFrame, curves: pd.DataFrame) -> dict:
    """A cell's agents (one per seed): held-out success and return over seeds, the least
    online steps among them, and at each budget the mean over seeds of their curves'
    success where every seed's curve has that budget."""
    row: dict = {"seeds": len(cell), "env_steps": int(cell["env_steps"].min())}
    measured = cell.dropna(subset=["success_rate"])
    if len(measured) == len(cell):
        stats = aggregate(measured.assign(group=0), ["group"]).iloc[0]
        row |= {
            "status": PUBLISHED,
            "success": stats["success_mean"],
            "success_ci_low": stats["success_ci_low"],
            "success_ci_high": stats["success_ci_high"],
            "return": stats["return_mean"],
            "held_out_episodes": int(cell["episodes"].sum()),
        }
    else:
        row["status"] = NO_HELD_OUT
    for budget in CURVE_BUDGETS:
        values = [
            _curve_success(curves[curves["agent"] == agent.agent], budget, agent.n_envs)
            for agent in cell.itertuples()
        ]
        row[f"curve_success_{budget}"] = np.mean(values) if not np.isnan(values).any() else np.nan
    return row


def _number(value: float, fmt: str) -> str:
    return "–" if pd.isna(value) else format(value, fmt)


def _steps(steps: float) -> str:
    """1,000,000 -> '1M', 250,000 -> '250k'."""
    return f"{steps / 1e6:g}M" if steps >= 1e6 else f"{steps / 1e3:g}k"


def agents_markdown(table: pd.DataFrame) -> str:
    """`agents_table` as a Markdown document: what it shows, then one row per cell ('not yet
    published' where no agent is)."""
    budgets = " | ".join(f"Curve {_steps(b)}" for b in CURVE_BUDGETS)
    lines = [
        "| Task | Reward | Held-out success % [95 %] | Held-out return | Online steps | Seeds "
        f"| Paper success % | Paper return | Paper steps | {budgets} |",
        "|---|---|---|---|---|---|---|---|---|" + "---|" * len(CURVE_BUDGETS),
    ]
    for r in table.to_dict("records"):
        if r["status"] == PUBLISHED:
            ours = (
                f"{r['success']:.1f} [{r['success_ci_low']:.1f}, {r['success_ci_high']:.1f}] "
                f"| {r['return']:.2f}"
            )
        else:
            ours = f"{r['status']} | –"
        steps = f"{int(r['env_steps']):,}" if r["status"] != NOT_PUBLISHED else "–"
        curve = [_number(r.get(f"curve_success_{b}", np.nan), ".1f") for b in CURVE_BUDGETS]
        lines.append(
            f"| {TASK_NAMES[r['task']]} | {r['reward']} | {ours} | {steps} | {r['seeds']} "
            f"| {r['paper_success']:.1f} | {r['paper_return']:.2f} | {r['paper_steps']:,} "
            f"| {' | '.join(curve)} |"
        )
    intro = (
        "# Table 1, TQC+HER: the published agents beside the paper\n\n"
        "Generated by `gcdt report` from `results/experts/tqc_*/` (`gcdt tqc publish`). "
        f"Held-out: the published model on its held-out episodes (seed {HELD_OUT_SEED}), "
        "success with "
        "its 95 % interval (Wilson over episodes for one seed, bootstrap over seeds for "
        "several). Curve N: success % of training's periodic evaluation at N env steps (its "
        "own episodes), where the run reached N. Paper: Table 1's TQC+HER values and the "
        "budget of its config (`gcdt/baselines/tqc_her.yaml`, `paper`)."
    )
    return intro + "\n\n" + "\n".join(lines)


def in_progress_table(agents_dir: str | Path = AGENTS_DIR) -> pd.DataFrame:
    """One row per run snapshotted in `agents_dir`'s in_progress/ folder (`gcdt tqc snapshot`):
    what it is (task, reward, seed, config), the env steps its snapshot holds, and at each
    budget of `CURVE_BUDGETS` it has reached, and at its latest evaluation, its success (%)
    beside that of the published agent of its task, reward and seed at the same steps (NaN
    where that agent's curve has no evaluation there)."""
    agents, curves = load_agents(agents_dir), load_agent_curves(agents_dir)
    snapshots = Path(agents_dir) / SNAPSHOTS_DIR.name
    rows = []
    for checkpoint in sorted(snapshots.glob(f"*/{CHECKPOINT_FILE}")):
        if checkpoint.parent.name.startswith("."):
            continue  # a snapshot being written (or left half-built by a kill), not one kept
        header = read_header(checkpoint)  # a damaged snapshot: one line naming it
        n_envs, steps = header["config"]["n_envs"], header["env_steps"]
        if not (checkpoint.parent / EVAL_CSV).is_file():
            raise GcdtError(
                f"{checkpoint.parent} has a checkpoint but no {EVAL_CSV}: snapshot the run "
                "again (gcdt tqc snapshot), or remove the folder"
            )
        curve = pd.read_csv(checkpoint.parent / EVAL_CSV)
        curve = curve[curve["env_steps"] < steps + n_envs]  # it may run ahead of the checkpoint
        agent = agents[
            (agents["task"] == header["task"])
            & (agents["reward"] == header["reward"])
            & (agents["seed"] == header["seed"])
        ]
        theirs = curves[curves["agent"].isin(agent["agent"])]
        their_envs = int(agent["n_envs"].iloc[0]) if len(agent) else n_envs
        row = {
            "run": checkpoint.parent.name,
            "task": header["task"],
            "reward": header["reward"],
            "seed": header["seed"],
            "config": header["config"]["name"],
            "env_steps": steps,
            "agent": agent["agent"].iloc[0] if len(agent) else None,
            "latest_steps": int(curve["env_steps"].iloc[-1]) if len(curve) else None,
        }
        for budget in CURVE_BUDGETS:
            row[f"success_{budget}"] = _curve_success(curve, budget, n_envs)
            row[f"agent_success_{budget}"] = _curve_success(theirs, budget, their_envs)
        if len(curve):
            # Either run's evaluation lands up to one loop iteration past the same mark.
            last = curve.iloc[-1]
            near = theirs[(theirs["env_steps"] - last["env_steps"]).abs() < max(n_envs, their_envs)]
            row["success_latest"] = 100 * float(last["success_rate"])
            row["agent_success_latest"] = (
                100 * float(near["success_rate"].iloc[0]) if len(near) else np.nan
            )
        rows.append(row)
    return pd.DataFrame(rows)


def in_progress_markdown(table: pd.DataFrame) -> str:
    """`in_progress_table` as a Markdown section ('' when no run is in progress)."""
    if table.empty:
        return ""

    def pair(r: dict, name: str) -> str:
        ours, theirs = r.get(f"success_{name}", np.nan), r.get(f"agent_success_{name}", np.nan)
        return f"{_number(ours, '.1f')} / {_number(theirs, '.1f')}"

    budgets = " | ".join(f"{_steps(b)}" for b in CURVE_BUDGETS)
    lines = [
        f"| Run | Config | Snapshot steps | Latest evaluation | {budgets} |",
        "|---|---|---|---|" + "---|" * len(CURVE_BUDGETS),
    ]
    for r in table.to_dict("records"):
        steps = r["latest_steps"]
        latest = "–" if pd.isna(steps) else f"{int(steps):,}: {pair(r, 'latest')}"
        cells = " | ".join(pair(r, str(b)) for b in CURVE_BUDGETS)
        lines.append(f"| {r['run']} | {r['config']} | {r['env_steps']:,} | {latest} | {cells} |")
    intro = (
        "## Runs in progress\n\n"
        f"From the snapshots in `results/experts/{SNAPSHOTS_DIR.name}/` (`gcdt tqc snapshot`). "
        "Success % of training's periodic evaluation: the run's / the published agent's of "
        "the same task, reward and seed at the same env steps (– where either has none)."
    )
    return intro + "\n\n" + "\n".join(lines)
