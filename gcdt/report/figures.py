"""Figures of the paper, as PNG and PDF under `figures/<profile>/`.

* Fig. 1: the three environments, rendered headless (`environments_figure`).
* Fig. 2: the GC-DT architecture, drawn from a model config (`architecture_figure`).
* Fig. 3 (RQ4): success rate against dataset size (`dataset_size_figure`).
* Fig. 4 (RQ5): success rate against the share of expert data (`expert_ratio_figure`).
* Beyond the paper: online steps against offline transitions (`online_offline_figure`).

Fig. 2-4 and the learning curves read only the run results (`tables.load_runs`); Fig. 3 and 4
draw one line per task, one panel per reward, the mean over seeds with its 95 % interval as
error bars (bootstrap over seeds; with one seed, Wilson over its evaluation episodes).
"""

from __future__ import annotations

import io
from pathlib import Path

import matplotlib.pyplot as plt
import pandas as pd
from matplotlib.ticker import NullFormatter

from gcdt.paths import figures_dir, write_if_changed
from gcdt.report.tables import (
    AGENT_KEY,
    METHOD_NAMES,
    TASK_NAMES,
    aggregate,
    curve_table,
    load_agent_curves,
)

FORMATS = ("png", "pdf")


#: No creation dates or tool versions in the files: the same figure gives the same bytes, so
#: re-rendering unchanged results leaves the published figures (and git) untouched.
METADATA = {
    "png": {"Software": None},
    "pdf": {"Creator": None, "Producer": None, "CreationDate": None},
}


def save(fig: plt.Figure, out_dir: str | Path, name: str) -> list[Path]:
    """Write `fig` as `name`.png and `name`.pdf into `out_dir` (only files whose bytes
    change are rewritten); return the paths."""
    out = Path(out_dir)
    paths = [out / f"{name}.{ext}" for ext in FORMATS]
    for path, ext in zip(paths, FORMATS, strict=True):
        buffer = io.BytesIO()
        fig.savefig(buffer, format=ext, dpi=150, bbox_inches="tight", metadata=METADATA[ext])
        write_if_changed(path, buffer.getvalue())
    plt.close(fig)
    return paths


def reward_panels(
    rewards: set[str], rows: int = 1, width: float = 5.0, height: float = 3.6, **kwargs
) -> tuple[plt.Figure, list, list[str]]:
    """A figure with one column of `rows` panels per reward in `rewards` (dense first, as in
    the paper's tables); returns it, its axes ([rows][columns]) and the rewards in order."""
    ordered = [r for r in ("dense", "sparse") if r in rewards]
    fig, axes = plt.subplots(
        rows, len(ordered), figsize=(width * len(ordered), height), squeeze=False, **kwargs
    )
    return fig, axes, ordered


def _success_panels(
    runs: pd.DataFrame, section: str, x: str, xlabel: str, scale: float = 1.0
) -> plt.Figure | None:
    """Success rate (%) against `x`: one panel per reward, one line per task, 95 % intervals
    (None when no run belongs to `section`)."""
    table = curve_table(runs, section, x)
    if table.empty:
        return None
    fig, axes, rewards = reward_panels(set(table["reward"]), sharey=True)
    for ax, reward in zip(axes[0], rewards, strict=True):
        for task in TASK_NAMES:
            stats = table[(table["reward"] == reward) & (table["task"] == task)]
            if stats.empty:
                continue
            mean = stats["success_mean"].to_numpy()
            ax.errorbar(
                stats[x] * scale,
                mean,
                yerr=[mean - stats["success_ci_low"], stats["success_ci_high"] - mean],
                marker="o",
                capsize=3,
                label=TASK_NAMES[task],
            )
        ax.set_title(f"{reward.capitalize()} reward")
        ax.set_xlabel(xlabel)
        ax.set_ylim(-5, 105)
        ax.grid(alpha=0.3)
        ax.legend()
    axes[0][0].set_ylabel("Success rate (%)")
    fig.tight_layout()
    return fig


def dataset_size_figure(runs: pd.DataFrame) -> plt.Figure | None:
    """Fig. 3 (RQ4): 'Impact of dataset size on success rate'."""
    fig = _success_panels(runs, "rq4", "size", "Dataset size (transitions)")
    if fig is not None:
        fig.suptitle("Impact of dataset size on success rate", y=1.03)
    return fig


def expert_ratio_figure(runs: pd.DataFrame) -> plt.Figure | None:
    """Fig. 4 (RQ5): 'Impact of expert data percentage'."""
    fig = _success_panels(runs, "rq5", "expert_ratio", "Expert data (%)", scale=100.0)
    if fig is not None:
        fig.suptitle("Impact of expert data percentage", y=1.03)
    return fig


def environments_figure(seed: int = 0) -> plt.Figure:
    """Fig. 1: Reach, Push and PickAndPlace at the start of a seeded episode."""
    from gcdt.envs import make_env

    fig, axes = plt.subplots(1, 3, figsize=(12, 4))
    for ax, (task, title) in zip(axes, TASK_NAMES.items(), strict=True):
        env = make_env(task, "sparse", render_width=480, render_height=480)
        try:
            env.reset(seed=seed)
            ax.imshow(env.render())
        finally:
            env.close()
        ax.set_title(title)
        ax.axis("off")
    fig.tight_layout()
    return fig


def architecture_figure(model_config: dict, task: str) -> plt.Figure:
    """Fig. 2: the GC-DT token sequence and layers, labelled from `model_config` (DTConfig)."""
    from gcdt.envs import get_task

    spec = get_task(task)
    k, hidden = model_config["context"], model_config["hidden"]
    layers, heads = model_config["layers"], model_config["heads"]
    fig, ax = plt.subplots(figsize=(11, 5))
    ax.set_xlim(0, 11)
    ax.set_ylim(0, 6.2)
    ax.axis("off")

    def box(x, y, w, h, text, color):
        ax.add_patch(plt.Rectangle((x, y), w, h, facecolor=color, edgecolor="black", lw=1))
        ax.text(x + w / 2, y + h / 2, text, ha="center", va="center", fontsize=8)

    tokens = [("\\hat R", "#f4cccc"), ("s", "#cfe2f3"), ("a", "#d9ead3")]
    for step, sub in enumerate(("t-2", "t-1", "t")):  # the newest steps of the K-step context
        for j, (symbol, color) in enumerate(tokens):
            x = 0.4 + step * 3.5 + j * 1.05
            box(x, 0.3, 0.9, 0.6, f"${symbol}_{{{sub}}}$", color)
            ax.annotate("", (x + 0.45, 1.6), (x + 0.45, 0.9), arrowprops={"arrowstyle": "->"})
    box(
        0.4,
        1.6,
        10.1,
        0.6,
        f"linear embeddings (hidden {hidden}) + timestep embedding, "
        "LayerNorm (no positional embedding)",
        "#fff2cc",
    )
    box(
        0.4,
        2.6,
        10.1,
        1.0,
        f"causal transformer: {layers} GPT-2 blocks, {heads} head(s), "
        f"ReLU MLP, dropout {model_config['dropout']}, context K = {k} steps ({3 * k} tokens)",
        "#eeeeee",
    )
    box(7.7, 4.2, 2.8, 0.6, "tanh action head on $s_t$ → $a_t$", "#d9ead3")
    ax.annotate("", (9.1, 4.2), (9.1, 3.6), arrowprops={"arrowstyle": "->"})
    state = (
        f"$s_t$ = [observation ({spec.obs_dim}), desired goal ({spec.goal_dim}), achieved "
        f"goal ({spec.goal_dim})] = {spec.state_dim} values on {TASK_NAMES.get(task, task)}"
    )
    ax.text(0.4, 5.3, state + "; $\\hat R_t$ = return-to-go / 100", fontsize=9)
    ax.set_title("Goal-Conditioned Decision Transformer")
    return fig


def learning_curves_figure(
    curves: dict[str, pd.DataFrame],
    x: str,
    y: str,
    xlabel: str,
    ylabel: str,
    title: str,
    logx: bool = False,
) -> plt.Figure:
    """One line per labelled curve (TQC+HER success against env steps, DT loss, ...).

    Points are marked when a curve has few of them (a one-point curve is otherwise
    invisible), and colours come from a 20-colour cycle so that a dozen curves stay apart.
    `logx` puts curves of very different lengths on one readable axis.
    """
    fig, ax = plt.subplots(figsize=(7, 4))
    colours = plt.get_cmap("tab20").colors
    for i, (label, frame) in enumerate(curves.items()):
        ax.plot(
            frame[x],
            frame[y] * (100 if y == "success_rate" else 1),
            label=label,
            color=colours[i % len(colours)],
            marker="o" if len(frame) <= 30 else None,
            markersize=4,
        )
    if y == "success_rate":
        ax.set_ylim(-5, 105)  # the whole scale: a flat curve at 0 % reads as 0 %, not as noise
    if logx:
        ax.set_xscale("log")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(alpha=0.3)
    if len(curves) > 1:
        ax.legend(fontsize=7, loc="center left", bbox_to_anchor=(1.01, 0.5))
    fig.tight_layout()
    return fig


def tqc_learning_curves_figure(runs: pd.DataFrame) -> plt.Figure | None:
    """TQC+HER's success rate against online env steps, from the runs' stored curves."""
    curves = {
        f"{r.task}/{r.reward} seed {r.seed}": pd.DataFrame(r.training["curve"])
        for r in runs[runs["method"] == "tqc"].itertuples()
        if r.training.get("curve")
    }
    if not curves:
        return None
    return learning_curves_figure(
        curves,
        "env_steps",
        "success_rate",
        "online env steps",
        "success rate (%)",
        "TQC+HER learning curves",
    )


def online_offline_figure(
    runs: pd.DataFrame, agents: pd.DataFrame | None = None, reward: str = "sparse"
) -> plt.Figure | None:
    """RQ1 at every budget: success against budget, one panel per task. TQC+HER's learning
    curve over online env steps (the grid's runs, mean over seeds, and the published agents'
    longer curves, `tables.load_agent_curves`) beside GC-DT and BC trained offline on that
    many expert transitions (the Table 1 and RQ4 runs, 95 % intervals, one series per
    training budget)."""
    agents = load_agent_curves() if agents is None else agents
    agents = agents[agents["reward"] == reward]
    runs = runs[runs["reward"] == reward]
    offline = runs[
        runs["method"].isin(["gcdt", "bc"])
        & (runs["expert_ratio"] == 1.0)
        & runs["sections"].apply(lambda s: "table1" in s or "rq4" in s)
    ]
    # The grid's TQC+HER runs; a profile's published-agent cells are among `agents` already.
    online = runs[(runs["method"] == "tqc") & ~runs["key"].str.startswith(AGENT_KEY)]
    tasks = [t for t in TASK_NAMES if t in set(offline["task"]) | set(agents["task"])]
    if not tasks:
        return None
    fig, axes = plt.subplots(
        1, len(tasks), figsize=(4.6 * len(tasks), 3.8), squeeze=False, sharex=True, sharey=True
    )
    for ax, task in zip(axes[0], tasks, strict=True):
        curves = [
            pd.DataFrame(r.training["curve"])
            for r in online[online["task"] == task].itertuples()
            if r.training.get("curve")
        ]
        if curves:
            mean = pd.concat(curves).groupby("env_steps")["success_rate"].mean()
            ax.plot(
                mean.index,
                mean * 100,
                color="tab:red",
                label=f"TQC+HER, grid ({len(curves)} seeds)",
            )
        for _, curve in agents[agents["task"] == task].groupby("agent"):
            ax.plot(
                curve["env_steps"], curve["success_rate"] * 100, color="tab:red", ls="--",
                label=f"TQC+HER, published agent (seed {curve['seed'].iloc[0]})",
            )  # fmt: skip
        task_runs = offline[offline["task"] == task]
        # BC's dots sit a little to the right, so that equal results do not hide GC-DT's.
        for method, colour, dodge in (("gcdt", "tab:blue", 1.0), ("bc", "tab:green", 1.08)):
            sel = task_runs[task_runs["method"] == method]
            # One series per training budget: a profile may give Table 1 a longer budget than
            # RQ4, and a dot that averaged seeds of two budgets would belong to neither.
            for i, (steps, budget) in enumerate(sel.groupby("train_steps")):
                marker = "osD^v"[i % 5]  # cycled, so that no budget's series is ever dropped
                stats = aggregate(budget, ["size"]).sort_values("size")
                m = stats["success_mean"].to_numpy()
                ax.errorbar(
                    stats["size"] * dodge, m,
                    yerr=[m - stats["success_ci_low"], stats["success_ci_high"] - m],
                    marker=marker, capsize=3, ls="", color=colour,
                    label=f"{METHOD_NAMES[method]}, offline on expert data, {int(steps):,} steps",
                )  # fmt: skip
        ax.set_xscale("log")
        ax.xaxis.set_minor_formatter(NullFormatter())  # decades only: minor labels collide
        ax.set_ylim(-5, 105)
        ax.set_title(f"{TASK_NAMES[task]}, {reward} reward")
        ax.set_xlabel("budget: online env steps / expert transitions")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="center right")  # the curves keep to the top and bottom
    axes[0][0].set_ylabel("Success rate (%)")
    fig.tight_layout()
    return fig


def training_loss_figure(runs: pd.DataFrame) -> plt.Figure | None:
    """The offline training loss of Table 1's GC-DT and BC runs, from the stored curves, on a
    log step axis: BC takes many more (smaller) steps for the same samples
    (`gcdt.experiments.grid.bc_steps`)."""
    table1 = runs[runs["sections"].apply(lambda s: "table1" in s)]
    curves = {
        f"{r.method} {r.task}/{r.reward} seed {r.seed}": pd.DataFrame(r.training["loss_curve"])
        for r in table1[table1["method"].isin(["gcdt", "bc"])].itertuples()
        if r.training.get("loss_curve")
    }
    if not curves:
        return None
    return learning_curves_figure(
        curves, "step", "loss", "gradient step", "action MSE", "Offline training loss", logx=True
    )


def table1_architecture_figure(runs: pd.DataFrame) -> plt.Figure | None:
    """Fig. 2 drawn from the model config stored with a Table 1 GC-DT run."""
    gcdt = runs[(runs["method"] == "gcdt") & runs["sections"].apply(lambda s: "table1" in s)]
    for r in gcdt.itertuples():
        if r.training.get("model_config"):
            return architecture_figure(r.training["model_config"], r.task)
    return None


def _attention_panel(ax: plt.Axes, weights, layer: int = -1) -> None:
    """The newest state token's attention over the context, one row per head of `layer`."""
    w = weights[layer][:, -2]  # the newest state token's query row (the last token is a_t)
    heads, n = w.shape
    ax.imshow(w, aspect="auto", cmap="viridis")
    ax.set_xticks(range(n), ["R", "s", "a"] * (n // 3), fontsize=6)
    ax.set_yticks(range(heads), [f"head {h}" for h in range(heads)])
    ax.set_xlabel("context tokens, oldest first (left padding gets no weight)")
    ax.set_title(f"Attention of the newest state token, layer {layer % len(weights)}")


def attention_figure(weights, layer: int = -1) -> plt.Figure:
    """What the newest state token attends to: one row per head of `layer`, tokens R, s, a
    per context step (`weights` from `TrainedPolicy.attention()`, `[layers, heads, 3K, 3K]`)."""
    heads, n = weights[layer][:, -2].shape
    fig, ax = plt.subplots(figsize=(max(6, n / 5), 1 + 0.6 * heads))
    _attention_panel(ax, weights, layer)
    fig.tight_layout()
    return fig


def rollout_figure(recording, threshold: float, weights=None) -> plt.Figure:
    """One recorded episode (`gcdt.evaluation.Recording`): its distance to the goal per step
    against the success threshold and, for a DT (`weights`), the final step's attention."""
    fig, axes = plt.subplots(
        1,
        2 if weights is not None else 1,
        figsize=(9 if weights is not None else 4, 3),
        gridspec_kw={"width_ratios": [1, 2.2]} if weights is not None else None,
        squeeze=False,
    )
    ax = axes[0, 0]
    ax.plot(range(len(recording.distances)), recording.distances, marker="o", ms=3)
    ax.axhline(threshold, color="tab:green", ls="--", lw=1, label=f"success: < {threshold} m")
    ax.set_xlabel("step")
    ax.set_ylabel("distance to the goal (m)")
    ax.set_ylim(bottom=0)
    ax.set_title(f"{recording.verdict}, return {recording.ret:.2f}")
    ax.legend(fontsize=8)
    if weights is not None:
        _attention_panel(axes[0, 1], weights)
    fig.tight_layout()
    return fig


__all__ = [
    "architecture_figure",
    "attention_figure",
    "dataset_size_figure",
    "environments_figure",
    "expert_ratio_figure",
    "figures_dir",
    "learning_curves_figure",
    "online_offline_figure",
    "rollout_figure",
    "save",
    "table1_architecture_figure",
    "tqc_learning_curves_figure",
    "training_loss_figure",
]
