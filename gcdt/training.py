"""One trainer for every method: the (GC-)DT and BC, from an offline `Dataset`.

The authors' recipe (their public code; its numbers are `gcdt.paper`'s): AdamW, linear warm-up
then linear decay, a gradient-norm clip, returns-to-go divided by a scale, states z-normalised
with the dataset's mean and std, K-step windows left-padded.
Windows start at a transition drawn uniformly from the whole dataset, which is exactly the
authors' "episode in proportion to its length, then a uniform start within it".

A budget is gradient steps, or the authors' epochs of ceil(#episodes / batch) steps each.
`train` is the loop; after each step two hooks log the loss and write checkpoints.
Checkpoints (`gcdt.checkpoint.TrainingState`) hold everything needed to resume (weights,
optimiser, schedule, RNG states), and on CPU a resumed run ends with the same weights as an
uninterrupted one. `TrainConfig` declares every setting once, with its help text, and
`gcdt train` takes each as an option.
"""

from __future__ import annotations

import csv
import ctypes
import functools
import math
import platform
import time
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any, Literal, get_args

import numpy as np
import torch

from gcdt import paper
from gcdt.checkpoint import (
    CHECKPOINT_NAME,
    MODELS,
    TrainingState,
    build_model,
    load_checkpoint,
)
from gcdt.data.dataset import Dataset
from gcdt.device import resolve_device
from gcdt.envs import RewardType, check_reward
from gcdt.errors import GcdtError
from gcdt.models import DTConfig, GoalConditioning, state_columns
from gcdt.paths import atomic_write
from gcdt.progress import progress_bar
from gcdt.settings import check_minimums, setting

Method = Literal["dt", "bc"]
METHODS: tuple[str, ...] = get_args(Method)
LOG_NAME = "train_log.csv"
#: TrainConfig fields that only decide when checkpoints are written, not what is learnt:
#: a run may be resumed with other values.
SCHEDULING_FIELDS = ("checkpoint_every", "checkpoint_seconds")
#: The model's shape defaults are `DTConfig`'s (BC shares its width, depth and dropout).
_MODEL_DEFAULTS = {f.name: f.default for f in fields(DTConfig)}


@dataclass(frozen=True)
class TrainConfig:
    """What to train and how; the defaults are the paper's."""

    method: Method = setting("dt", "dt: a Decision Transformer; bc: behavioural cloning")
    goal_conditioning: GoalConditioning = setting(
        "desired+achieved",
        "what the state holds besides the observation; desired+achieved is the paper's GC-DT",
    )
    reward: RewardType = setting("sparse", "the rewards that make the returns-to-go")
    steps: int | None = setting(None, "gradient steps", minimum=1)
    epochs: int | None = setting(
        None,
        "the authors' epochs of ceil(#episodes / batch size) steps; "
        f"neither steps nor epochs given: {paper.EPOCHS} epochs",
        minimum=1,
    )
    batch_size: int = setting(
        paper.BATCH_SIZE, "windows (DT) or transitions (BC) per step", minimum=1
    )
    lr: float = setting(paper.LEARNING_RATE, "AdamW peak learning rate")
    weight_decay: float = setting(paper.WEIGHT_DECAY, "AdamW weight decay")
    warmup_fraction: float = setting(
        paper.WARMUP_FRACTION, "share of the steps of linear warm-up, then decay"
    )
    grad_clip: float = setting(paper.GRAD_CLIP, "gradient-norm clip")
    return_scale: float = setting(paper.RETURN_SCALE, "returns-to-go are divided by this")
    context: int = setting(
        _MODEL_DEFAULTS["context"],
        "K, the steps a DT sees (return-to-go, state, action)",
        minimum=1,
    )
    hidden: int = setting(_MODEL_DEFAULTS["hidden"], "the model's width", minimum=1)
    layers: int = setting(
        _MODEL_DEFAULTS["layers"], "transformer blocks, or BC's hidden layers", minimum=1
    )
    heads: int = setting(_MODEL_DEFAULTS["heads"], "attention heads (DT)", minimum=1)
    dropout: float = setting(_MODEL_DEFAULTS["dropout"], "dropout probability")
    seed: int = setting(0, "seeds the initial weights, dropout and batches", minimum=0)
    device: str = setting("auto", "auto (CUDA when present, else CPU), cpu, cuda or cuda:N")
    bf16: bool = setting(False, "bfloat16 autocast for the forward pass")
    log_every: int = setting(50, "a train_log.csv row every this many steps", minimum=1)
    checkpoint_every: int = setting(1000, "a checkpoint every this many steps", minimum=1)
    checkpoint_seconds: float = setting(
        30.0,
        "at most this many seconds between checkpoints (and log writes), besides one "
        "every checkpoint_every steps",
    )

    def __post_init__(self) -> None:
        if self.method not in METHODS:
            raise GcdtError(f"unknown method {self.method!r}: expected one of {', '.join(METHODS)}")
        check_reward(self.reward)
        if self.steps is not None and self.epochs is not None:
            raise GcdtError("give one budget, steps or epochs, not both")
        check_minimums(self)
        # Real-valued settings and their ranges; NaN fails every comparison, so it is refused.
        for name, ok, wanted in (
            ("lr", lambda v: v > 0, "> 0"),
            ("weight_decay", lambda v: v >= 0, ">= 0"),
            ("warmup_fraction", lambda v: 0 <= v <= 1, "in [0, 1]"),
            ("grad_clip", lambda v: v > 0, "> 0"),
            ("return_scale", lambda v: v > 0, "> 0"),
            ("dropout", lambda v: 0 <= v < 1, "in [0, 1)"),
            ("checkpoint_seconds", lambda v: v > 0, "> 0"),
        ):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | float) or not ok(value):
                raise GcdtError(f"{name} must be {wanted}, got {value!r}")

    def total_steps(self, n_episodes: int) -> int:
        if self.steps is not None:
            return self.steps
        return (self.epochs or paper.EPOCHS) * math.ceil(n_episodes / self.batch_size)

    def model_config(self, state_dim: int, action_dim: int) -> dict[str, Any]:
        """The config of the model to train, as a checkpoint stores it: `DTConfig` or
        `BCConfig` with this config's values of their fields (context, hidden, ...)."""
        config_class = MODELS[self.method][0]
        own = {f.name for f in fields(self)}
        shape = {f.name: getattr(self, f.name) for f in fields(config_class) if f.name in own}
        return asdict(config_class(state_dim, action_dim, **shape))


class WindowSampler:
    """Batches of K-step windows (DT) or single transitions (BC), gathered on the device.

    All arrays live on the device once; a batch is an index computation and one gather.
    """

    def __init__(
        self,
        dataset: Dataset,
        cfg: TrainConfig,
        mean: np.ndarray,
        std: np.ndarray,
        device: torch.device,
    ) -> None:
        cols = state_columns(dataset.task, cfg.goal_conditioning)
        states = (dataset.states[:, cols] - mean) / std
        rtg = dataset.returns_to_go(cfg.reward) / cfg.return_scale

        def put(a: np.ndarray) -> torch.Tensor:
            return torch.as_tensor(np.ascontiguousarray(a)).to(device)

        self.states = put(states.astype(np.float32))
        self.actions = put(dataset.actions)
        self.rtg = put(rtg.astype(np.float32))
        # Episodes longer than the timestep table share its last entry, as in the policy.
        last_timestep = _MODEL_DEFAULTS["max_episode_steps"] - 1
        self.timesteps = put(np.minimum(dataset.timesteps, last_timestep))
        self.ends = put(dataset.offsets[1:][dataset.episode_index])  # episode end of each row
        self.n, self.k, self.batch = len(dataset), cfg.context, cfg.batch_size
        self.method, self.device = cfg.method, device
        self.arange = torch.arange(self.k, device=device)

    def sample(self, rng: np.random.Generator) -> dict[str, torch.Tensor]:
        start = torch.as_tensor(rng.integers(0, self.n, self.batch), device=self.device)
        if self.method == "bc":
            return {"states": self.states[start], "actions": self.actions[start]}
        n_valid = torch.clamp(self.ends[start] - start, max=self.k)  # [batch]
        pad = self.k - n_valid
        mask = self.arange[None, :] >= pad[:, None]  # [batch, K], False on the left padding
        idx = torch.where(mask, start[:, None] + self.arange[None, :] - pad[:, None], 0)
        m = mask[..., None]
        return {
            "states": self.states[idx] * m,
            "actions": self.actions[idx] * m,
            "returns_to_go": (self.rtg[idx] * mask)[..., None],
            "timesteps": self.timesteps[idx] * mask,
            "mask": mask,
        }


def _loss(model: torch.nn.Module, batch: dict[str, torch.Tensor], method: str) -> torch.Tensor:
    if method == "bc":
        return torch.mean((model(batch["states"]) - batch["actions"]) ** 2)
    pred = model(
        batch["states"], batch["actions"], batch["returns_to_go"], batch["timesteps"], batch["mask"]
    )
    return torch.mean((pred - batch["actions"])[batch["mask"]] ** 2)  # real tokens only


@functools.cache
def keep_freed_memory() -> bool:
    """Let glibc's malloc keep freed memory for reuse instead of handing it back to the OS.

    A CPU training step allocates and frees tensors of several MB. By default glibc maps each
    one afresh and unmaps it when freed, so every step pays page faults on first touch (the
    torch profiler shows them in the DT step's ReLU forward and backward on [64, 60, 512]).
    Raising the mmap and trim thresholds keeps those blocks in the heap. Process-wide and
    idempotent; returns False where libc is not glibc.
    """
    if platform.system() != "Linux" or platform.libc_ver()[0] != "glibc":
        return False
    libc = ctypes.CDLL(None)
    m_trim_threshold, m_top_pad, m_mmap_threshold = -1, -2, -3  # <malloc.h>
    return all(
        (
            libc.mallopt(m_mmap_threshold, 32 << 20),  # glibc's maximum on 64-bit
            libc.mallopt(m_trim_threshold, 1 << 30),
            libc.mallopt(m_top_pad, 64 << 20),
        )
    )


def make_optimizer(model: torch.nn.Module, cfg: TrainConfig) -> torch.optim.Optimizer:
    """The authors' AdamW; fused (one kernel for all parameters, same update rule), which
    on CPU shrinks the optimiser's share of a DT step."""
    return torch.optim.AdamW(
        model.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay, fused=True
    )


def train_step(
    model: torch.nn.Module,
    optimizer: torch.optim.Optimizer,
    batch: dict[str, torch.Tensor],
    cfg: TrainConfig,
    device: torch.device,
) -> torch.Tensor:
    """One optimiser step on `batch`; returns the loss. A non-finite loss updates nothing."""
    with torch.autocast(device.type, dtype=torch.bfloat16, enabled=cfg.bf16):
        loss = _loss(model, batch, cfg.method)
    if not torch.isfinite(loss):
        return loss
    optimizer.zero_grad(set_to_none=True)
    loss.backward()
    torch.nn.utils.clip_grad_norm_(model.parameters(), cfg.grad_clip, foreach=True)
    optimizer.step()
    return loss


@dataclass
class TrainResult:
    """Where the outputs are and what the run cost."""

    checkpoint: Path
    log: Path
    steps: int
    seconds: float
    final_loss: float
    history: list[dict[str, float]] = field(default_factory=list)
    resumed_from: int = 0  # the step this call began at: `seconds` paid for the steps after it


def train(
    dataset: Dataset,
    cfg: TrainConfig,
    out_dir: str | Path,
    *,
    resume: bool = False,
    stop_after: int | None = None,
    progress: bool = True,
) -> TrainResult:
    """Train `cfg.method` on `dataset`; write `checkpoint.pt` and `train_log.csv` to `out_dir`.

    With `resume`, continue from `out_dir/checkpoint.pt` (same config required).
    `stop_after` ends this call after that many more steps (checkpointed), e.g. to split a
    long run into sessions; a later `resume=True` call finishes it.
    """
    out_dir = Path(out_dir)
    identity, state = _start(dataset, cfg, out_dir, resume)
    first = state.step
    sampler = WindowSampler(dataset, cfg, state.state_mean, state.state_std, state.device)
    total = identity["total_steps"]
    end = total if stop_after is None else min(total, state.step + stop_after)
    checkpoints = _Checkpoints(out_dir, identity, cfg, end)
    log = _LossLog(cfg, total, out_dir, state.step, f"{cfg.method} on {dataset.task}", progress)
    state.model.train()
    with log:
        while state.step < end:
            batch = sampler.sample(state.rng)
            loss = train_step(state.model, state.optimizer, batch, cfg, state.device)
            if not torch.isfinite(loss):
                raise GcdtError(
                    f"training loss became {loss.item()} at step {state.step}: stopped; "
                    f"the last good checkpoint is {checkpoints.last_good()}"
                )
            state.schedule.step()
            state.step += 1
            log.after_step(state, loss.item())
            checkpoints.after_step(state)
    checkpoints.save(state, complete=state.step >= total)
    final_loss = state.history[-1]["loss"] if state.history else float("nan")
    seconds = time.perf_counter() - log.started
    return TrainResult(
        checkpoints.path, checkpoints.log, state.step, seconds, final_loss, state.history, first
    )


def _start(
    dataset: Dataset, cfg: TrainConfig, out_dir: Path, resume: bool
) -> tuple[dict[str, Any], TrainingState]:
    """The run's identity (what its checkpoint names it by) and its state at the first step
    of this call: fresh, or with `resume` restored from the checkpoint in `out_dir`."""
    ckpt_path = out_dir / CHECKPOINT_NAME
    if ckpt_path.exists() and not resume:
        raise GcdtError(
            f"{out_dir} already holds a checkpoint: resume it (--resume) or choose another --out"
        )
    device = resolve_device(cfg.device)
    if device.type == "cpu":
        keep_freed_memory()
    cols = state_columns(dataset.task, cfg.goal_conditioning)
    total = cfg.total_steps(dataset.n_episodes)
    identity = {
        "method": cfg.method,
        "task": dataset.task,
        "train_config": asdict(cfg),
        "model_config": cfg.model_config(cols.stop, dataset.spec.action_dim),
        "total_steps": total,
        "dataset": dataset.summary(),
    }
    torch.manual_seed(cfg.seed)
    model = build_model(cfg.method, identity["model_config"]).to(device)
    optimizer = make_optimizer(model, cfg)
    state = TrainingState(
        model, optimizer, _schedule(optimizer, cfg, total), np.random.default_rng(cfg.seed), device
    )
    if not resume:
        states = dataset.states[:, cols].astype(np.float64)
        state.state_mean = states.mean(axis=0).astype(np.float32)
        state.state_std = (states.std(axis=0) + 1e-6).astype(np.float32)  # as the authors' code
        return identity, state
    ckpt = load_checkpoint(ckpt_path)
    if _learning_config(ckpt["train_config"]) != _learning_config(identity["train_config"]) or (
        ckpt["task"] != dataset.task
    ):
        raise GcdtError(f"{ckpt_path} was trained with another config or task: cannot resume")
    state.restore(ckpt)
    return identity, state


def _schedule(
    optimizer: torch.optim.Optimizer, cfg: TrainConfig, total: int
) -> torch.optim.lr_scheduler.LambdaLR:
    """Linear warm-up over `warmup_fraction` of the steps, then linear decay to 0."""
    warmup = max(1, int(cfg.warmup_fraction * total))
    return torch.optim.lr_scheduler.LambdaLR(
        optimizer, lambda s: min((s + 1) / warmup, max(0.0, (total - s) / max(1, total - warmup)))
    )


class _LossLog:
    """The logging hook: a history row (mean loss since the last row, learning rate, seconds)
    every `log_every` steps and at the last, on the progress bar and in TensorBoard too."""

    def __init__(
        self, cfg: TrainConfig, total: int, out_dir: Path, step: int, run: str, progress: bool
    ) -> None:
        self.every, self.total = cfg.log_every, total
        self.board = _tensorboard(out_dir)
        self.bar = progress_bar(
            total=total, initial=step, desc=f"train {run}", progress=progress, leave=False
        )
        self.started = time.perf_counter()

    def after_step(self, state: TrainingState, loss: float) -> None:
        state.window_loss += loss
        state.window_steps += 1
        self.bar.update(1)
        if state.step % self.every and state.step != self.total:
            return
        row = {
            "step": state.step,
            "loss": state.window_loss / state.window_steps,
            "lr": state.schedule.get_last_lr()[0],
            "seconds": time.perf_counter() - self.started,
        }
        state.history.append(row)
        state.window_loss, state.window_steps = 0.0, 0
        self.bar.set_postfix(loss=f"{row['loss']:.4f}")
        if self.board is not None:
            self.board.add_scalar("train/loss", row["loss"], state.step)
            self.board.add_scalar("train/lr", row["lr"], state.step)

    def __enter__(self) -> _LossLog:
        return self

    def __exit__(self, *exc: object) -> None:
        self.bar.close()
        if self.board is not None:
            self.board.close()


class _Checkpoints:
    """The checkpoint hook: the log and a checkpoint every `checkpoint_every` steps and at most
    `checkpoint_seconds` apart, so that a killed run loses at most that much work."""

    def __init__(self, out_dir: Path, identity: dict[str, Any], cfg: TrainConfig, end: int):
        self.path, self.log = out_dir / CHECKPOINT_NAME, out_dir / LOG_NAME
        self.identity, self.end = identity, end
        self.every, self.seconds = cfg.checkpoint_every, cfg.checkpoint_seconds
        self.last_save = time.perf_counter()

    def after_step(self, state: TrainingState) -> None:
        if state.step < self.end and (
            state.step % self.every == 0 or time.perf_counter() - self.last_save >= self.seconds
        ):
            self.save(state, complete=False)

    def save(self, state: TrainingState, *, complete: bool) -> None:
        # The log first: wherever a checkpoint exists, a log at least as recent does too.
        _write_log(self.log, state.history)
        state.save(self.path, self.identity, complete=complete)
        self.last_save = time.perf_counter()

    def last_good(self) -> str:
        return str(self.path) if self.path.exists() else "none (none written yet)"


def _tensorboard(out_dir: Path):
    """A TensorBoard writer into `out_dir/tensorboard` when tensorboard is installed."""
    try:
        from torch.utils.tensorboard import SummaryWriter
    except ImportError:  # optional: the CSV log is always written
        return None
    return SummaryWriter(str(out_dir / "tensorboard"))


def _learning_config(train_config: dict[str, Any]) -> dict[str, Any]:
    """A config as `asdict` gives it, less the checkpoint schedule: what resuming compares."""
    return {k: v for k, v in train_config.items() if k not in SCHEDULING_FIELDS}


def _write_log(path: Path, history: list[dict[str, float]]) -> None:
    """The CSV training log (step, loss, lr, seconds), written atomically."""
    with atomic_write(path) as f:
        writer = csv.DictWriter(f, fieldnames=["step", "loss", "lr", "seconds"])
        writer.writeheader()
        writer.writerows(history)
