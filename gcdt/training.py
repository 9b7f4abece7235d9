"""One trainer for every method: the (GC-)DT and BC, from an offline `Dataset`.

The authors' recipe (their public code): AdamW (lr 1e-4, weight decay 1e-4), linear warm-up over
10 % of the steps then linear decay, gradient-norm clip 0.25, batch 64, returns-to-go divided
by 100, states z-normalised with the dataset's mean and std, K-step windows left-padded.
Windows start at a transition drawn uniformly from the whole dataset, which is exactly the
authors' "episode in proportion to its length, then a uniform start within it".

A budget is gradient steps, or the authors' epochs of ceil(#episodes / batch) steps each.
Checkpoints hold everything needed to resume (weights, optimiser, schedule, RNG states), and
on CPU a resumed run ends with the same weights as an uninterrupted one.
"""

from __future__ import annotations

import csv
import ctypes
import functools
import math
import platform
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
import torch

from gcdt.data.dataset import Dataset
from gcdt.envs import check_reward
from gcdt.errors import GcdtError
from gcdt.models import BCConfig, BCPolicyNet, DTConfig, GoalConditionedDT, state_columns
from gcdt.paths import atomic_write
from gcdt.progress import progress_bar
from gcdt.provenance import package_versions, utc_now

Method = Literal["dt", "bc"]
METHODS: tuple[str, ...] = ("dt", "bc")
CHECKPOINT_FORMAT = "gcdt.checkpoint"
CHECKPOINT_VERSION = 1
CHECKPOINT_NAME = "checkpoint.pt"
LOG_NAME = "train_log.csv"
PAPER_EPOCHS = 120
#: TrainConfig fields that only decide when checkpoints are written, not what is learnt:
#: a run may be resumed with other values.
SCHEDULING_FIELDS = ("checkpoint_every", "checkpoint_seconds")


@dataclass(frozen=True)
class TrainConfig:
    """What to train and how; the defaults are the paper's."""

    method: Method = "dt"
    goal_conditioning: str = "desired+achieved"  # "desired+achieved" = the paper's GC-DT
    reward: str = "sparse"  # which rewards make the returns-to-go
    steps: int | None = None  # gradient steps; or
    epochs: int | None = None  # the authors' epochs of ceil(#episodes / batch_size) steps;
    # neither given: the paper's 120 epochs
    batch_size: int = 64
    lr: float = 1e-4
    weight_decay: float = 1e-4
    warmup_fraction: float = 0.1
    grad_clip: float = 0.25
    return_scale: float = 100.0
    context: int = 20  # K (DT only)
    hidden: int = 128
    layers: int = 3
    heads: int = 1
    dropout: float = 0.1
    seed: int = 0
    device: str = "auto"  # "auto" = CUDA when present, else CPU
    bf16: bool = False  # bfloat16 autocast for the forward pass
    log_every: int = 50
    checkpoint_every: int = 1000  # a checkpoint every this many steps,
    checkpoint_seconds: float = 30.0  # and whenever this many seconds passed since the last

    def __post_init__(self) -> None:
        if self.method not in METHODS:
            raise GcdtError(f"unknown method {self.method!r}: expected one of {', '.join(METHODS)}")
        check_reward(self.reward)
        if self.steps is not None and self.epochs is not None:
            raise GcdtError("give one budget, steps or epochs, not both")
        for name in ("steps", "epochs", "batch_size", "context", "log_every", "checkpoint_every"):
            value = getattr(self, name)
            if value is not None and (not isinstance(value, int) or value < 1):
                raise GcdtError(f"{name} must be a positive integer, got {value!r}")
        if not self.lr > 0:
            raise GcdtError(f"lr must be > 0, got {self.lr!r}")
        if isinstance(self.checkpoint_seconds, bool) or not self.checkpoint_seconds > 0:
            raise GcdtError(f"checkpoint_seconds must be > 0, got {self.checkpoint_seconds!r}")

    def total_steps(self, n_episodes: int) -> int:
        if self.steps is not None:
            return self.steps
        return (self.epochs or PAPER_EPOCHS) * math.ceil(n_episodes / self.batch_size)


def method_label(method: str, goal_conditioning: str) -> str:
    """How results name a method: `gcdt` (the paper's), `dt` (no goals), `dt-desired`, `bc`."""
    if method == "bc":
        return "bc"
    return {"desired+achieved": "gcdt", "none": "dt"}.get(goal_conditioning, "dt-desired")


def resolve_device(device: str) -> torch.device:
    """`auto` (CUDA when present, else CPU), `cpu`, `cuda` or `cuda:N`, checked here so that
    a wrong name or a missing GPU fails at once with a fix, not deep inside a run."""
    if device == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    try:
        resolved = torch.device(device)
    except (RuntimeError, TypeError):
        resolved = None
    if resolved is None or resolved.type not in ("cpu", "cuda"):
        raise GcdtError(f"unknown device {device!r}: use auto, cpu, cuda or cuda:N")
    if resolved.type == "cuda" and not torch.cuda.is_available():
        raise GcdtError(f"device {device!r}: this torch sees no CUDA GPU; use cpu or auto")
    return resolved


def build_model(method: str, model_config: dict[str, Any]) -> torch.nn.Module:
    if method == "dt":
        return GoalConditionedDT(DTConfig(**model_config))
    return BCPolicyNet(BCConfig(**model_config))


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
        last_timestep = DTConfig.__dataclass_fields__["max_episode_steps"].default - 1
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
    one afresh and unmaps it when freed, so every step pays page faults on first touch: on a
    2-core EPYC a quarter of the DT step (torch profiler, ReLU forward and backward on
    [64, 60, 512] took 3x longer). Raising the mmap and trim thresholds keeps those blocks
    in the heap. Process-wide and idempotent; returns False where libc is not glibc.
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
    on CPU cuts the optimiser's share of a DT step from 4 % to 1 %."""
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
    ckpt_path, log_path = out_dir / CHECKPOINT_NAME, out_dir / LOG_NAME
    if ckpt_path.exists() and not resume:
        raise GcdtError(
            f"{out_dir} already holds a checkpoint: resume it (--resume) or choose another --out"
        )
    device = resolve_device(cfg.device)
    if device.type == "cpu":
        keep_freed_memory()
    cols = state_columns(dataset.task, cfg.goal_conditioning)
    total = cfg.total_steps(dataset.n_episodes)
    state_dim, action_dim = cols.stop, dataset.spec.action_dim
    if cfg.method == "dt":
        model_config = asdict(
            DTConfig(
                state_dim, action_dim, cfg.context, cfg.hidden, cfg.layers, cfg.heads, cfg.dropout
            )
        )
    else:
        model_config = asdict(BCConfig(state_dim, action_dim, cfg.hidden, cfg.layers, cfg.dropout))

    torch.manual_seed(cfg.seed)
    model = build_model(cfg.method, model_config).to(device)
    optimizer = make_optimizer(model, cfg)
    warmup = max(1, int(cfg.warmup_fraction * total))
    schedule = torch.optim.lr_scheduler.LambdaLR(
        optimizer, lambda s: min((s + 1) / warmup, max(0.0, (total - s) / max(1, total - warmup)))
    )
    rng = np.random.default_rng(cfg.seed)
    step, history = 0, []
    window_loss, window_steps = 0.0, 0  # losses since the last log row
    if resume:
        ckpt = load_checkpoint(ckpt_path)
        if _learning_config(ckpt["train_config"]) != _learning_config(asdict(cfg)) or (
            ckpt["task"] != dataset.task
        ):
            raise GcdtError(f"{ckpt_path} was trained with another config or task: cannot resume")
        model.load_state_dict(ckpt["model"])
        optimizer.load_state_dict(ckpt["optimizer"])
        schedule.load_state_dict(ckpt["schedule"])
        rng.bit_generator.state = ckpt["rng"]["numpy"]
        torch.set_rng_state(ckpt["rng"]["torch"])
        if device.type == "cuda" and ckpt["rng"].get("cuda") is not None:
            # Dropout on a GPU draws from the device's generator, not the CPU one.
            torch.cuda.set_rng_state(ckpt["rng"]["cuda"], device)
        mean, std = ckpt["state_mean"].numpy(), ckpt["state_std"].numpy()
        step, history = ckpt["step"], ckpt["history"]
        window_loss, window_steps = ckpt["log_window"]
    else:
        states = dataset.states[:, cols].astype(np.float64)
        mean = states.mean(axis=0).astype(np.float32)
        std = (states.std(axis=0) + 1e-6).astype(np.float32)  # as the authors' code
    sampler = WindowSampler(dataset, cfg, mean, std, device)

    def save(complete: bool) -> None:
        nonlocal last_save
        # The log first: wherever a checkpoint exists, a log at least as recent does too.
        _write_log(log_path, history)
        save_checkpoint(
            ckpt_path,
            {
                "format": CHECKPOINT_FORMAT,
                "version": CHECKPOINT_VERSION,
                "method": cfg.method,
                "task": dataset.task,
                "train_config": asdict(cfg),
                "model_config": model_config,
                "model": model.state_dict(),
                "optimizer": optimizer.state_dict(),
                "schedule": schedule.state_dict(),
                "state_mean": torch.as_tensor(mean),
                "state_std": torch.as_tensor(std),
                "rng": {
                    "numpy": rng.bit_generator.state,
                    "torch": torch.get_rng_state(),
                    "cuda": torch.cuda.get_rng_state(device) if device.type == "cuda" else None,
                },
                "step": step,
                "total_steps": total,
                "complete": complete,
                "history": history,
                "log_window": [window_loss, window_steps],
                "dataset": dataset.summary(),
                "created": utc_now(),
                "versions": package_versions(),
            },
        )
        last_save = time.perf_counter()

    end = total if stop_after is None else min(total, step + stop_after)
    board = _tensorboard(out_dir)
    bar = progress_bar(
        total=total,
        initial=step,
        desc=f"train {cfg.method} on {dataset.task}",
        progress=progress,
        leave=False,
    )
    model.train()
    started = last_save = time.perf_counter()
    try:
        while step < end:
            loss = train_step(model, optimizer, sampler.sample(rng), cfg, device)
            if not torch.isfinite(loss):
                last = ckpt_path if ckpt_path.exists() else "none (none written yet)"
                raise GcdtError(
                    f"training loss became {loss.item()} at step {step}: stopped; "
                    f"the last good checkpoint is {last}"
                )
            schedule.step()
            step += 1
            window_loss += loss.item()
            window_steps += 1
            bar.update(1)
            if step % cfg.log_every == 0 or step == total:
                history.append(
                    {
                        "step": step,
                        "loss": window_loss / window_steps,
                        "lr": schedule.get_last_lr()[0],
                        "seconds": time.perf_counter() - started,
                    }
                )
                bar.set_postfix(loss=f"{history[-1]['loss']:.4f}")
                if board is not None:
                    board.add_scalar("train/loss", history[-1]["loss"], step)
                    board.add_scalar("train/lr", history[-1]["lr"], step)
                window_loss, window_steps = 0.0, 0
            # By steps and by the clock: a killed run loses at most checkpoint_seconds of work.
            if step < end and (
                step % cfg.checkpoint_every == 0
                or time.perf_counter() - last_save >= cfg.checkpoint_seconds
            ):
                save(complete=False)
    finally:
        bar.close()
        if board is not None:
            board.close()
    save(complete=step >= total)
    return TrainResult(
        ckpt_path,
        log_path,
        step,
        time.perf_counter() - started,
        history[-1]["loss"] if history else float("nan"),
        history,
    )


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


def save_checkpoint(path: Path, payload: dict[str, Any]) -> None:
    """`torch.save` through a temp file and a rename: never half a checkpoint."""
    with atomic_write(path, binary=True) as f:
        torch.save(payload, f)


def load_checkpoint(path: str | Path) -> dict[str, Any]:
    """A checkpoint written by `train`, loaded without running code (`weights_only`)."""
    path = Path(path)
    if not path.is_file():
        raise GcdtError(f"checkpoint {str(path)!r} does not exist")
    try:
        ckpt = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as err:
        raise GcdtError(
            f"{path} is not a readable gcdt checkpoint ({type(err).__name__})"
        ) from None
    if not isinstance(ckpt, dict) or ckpt.get("format") != CHECKPOINT_FORMAT:
        raise GcdtError(f"{path} is not a gcdt checkpoint")
    if ckpt.get("version") != CHECKPOINT_VERSION:
        raise GcdtError(
            f"{path} has checkpoint version {ckpt.get('version')}, this gcdt reads "
            f"{CHECKPOINT_VERSION}: retrain it"
        )
    return ckpt
