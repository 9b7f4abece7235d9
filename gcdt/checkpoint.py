"""Checkpoints of offline training: written by `gcdt.training`, read by it (to resume) and by
`gcdt.policies.trained` (to act), so that a policy never needs the trainer.

A checkpoint is one `torch.save`d dict (format `CHECKPOINT_FORMAT`, version
`CHECKPOINT_VERSION`) named `CHECKPOINT_NAME` in its run folder. It holds the run's identity
(method, task, `train_config` and `model_config` as plain dicts, total steps, the dataset's
summary) and its `TrainingState`: the weights, the state normalisation, and everything else a
resumed run needs (optimiser, schedule, RNG states, step, loss history).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from gcdt.errors import GcdtError
from gcdt.models import BCConfig, BCPolicyNet, DTConfig, GoalConditionedDT
from gcdt.paths import atomic_write
from gcdt.provenance import package_versions, utc_now

CHECKPOINT_FORMAT = "gcdt.checkpoint"
CHECKPOINT_VERSION = 1
CHECKPOINT_NAME = "checkpoint.pt"
#: Each trainer method's model: (config class, model class).
MODELS: dict[str, tuple[type, type[torch.nn.Module]]] = {
    "dt": (DTConfig, GoalConditionedDT),
    "bc": (BCConfig, BCPolicyNet),
}


def build_model(method: str, model_config: dict[str, Any]) -> torch.nn.Module:
    """The untrained model of `method` ("dt" or "bc") with a checkpoint's `model_config`."""
    config_class, model_class = MODELS[method]
    return model_class(config_class(**model_config))


@dataclass
class TrainingState:
    """What a training run carries from one step to the next, all of it in its checkpoint."""

    model: torch.nn.Module
    optimizer: torch.optim.Optimizer
    schedule: torch.optim.lr_scheduler.LRScheduler
    rng: np.random.Generator  # draws the batches
    device: torch.device
    state_mean: np.ndarray | None = None  # the state normalisation, fixed at the first step
    state_std: np.ndarray | None = None
    step: int = 0
    history: list[dict[str, float]] = field(default_factory=list)  # the log's rows
    window_loss: float = 0.0  # the losses summed since the last log row
    window_steps: int = 0

    def restore(self, ckpt: dict[str, Any]) -> None:
        """Continue from `ckpt`, a checkpoint of the same run (the caller checks that)."""
        self.model.load_state_dict(ckpt["model"])
        self.optimizer.load_state_dict(ckpt["optimizer"])
        self.schedule.load_state_dict(ckpt["schedule"])
        self.rng.bit_generator.state = ckpt["rng"]["numpy"]
        torch.set_rng_state(ckpt["rng"]["torch"])
        if self.device.type == "cuda" and ckpt["rng"].get("cuda") is not None:
            # Dropout on a GPU draws from the device's generator, not the CPU one.
            torch.cuda.set_rng_state(ckpt["rng"]["cuda"], self.device)
        self.state_mean, self.state_std = ckpt["state_mean"].numpy(), ckpt["state_std"].numpy()
        self.step, self.history = ckpt["step"], ckpt["history"]
        self.window_loss, self.window_steps = ckpt["log_window"]

    def save(self, path: Path, identity: dict[str, Any], *, complete: bool) -> None:
        """Write the checkpoint of the run `identity` names (method, task, train_config,
        model_config, total_steps, dataset) at this state; `complete` once it is finished."""
        cuda = self.device.type == "cuda"
        payload = {
            "format": CHECKPOINT_FORMAT,
            "version": CHECKPOINT_VERSION,
            **identity,
            "model": self.model.state_dict(),
            "optimizer": self.optimizer.state_dict(),
            "schedule": self.schedule.state_dict(),
            "state_mean": torch.as_tensor(self.state_mean),
            "state_std": torch.as_tensor(self.state_std),
            "rng": {
                "numpy": self.rng.bit_generator.state,
                "torch": torch.get_rng_state(),
                "cuda": torch.cuda.get_rng_state(self.device) if cuda else None,
            },
            "step": self.step,
            "complete": complete,
            "history": self.history,
            "log_window": [self.window_loss, self.window_steps],
            "created": utc_now(),
            "versions": package_versions(),
        }
        save_checkpoint(path, payload)


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
