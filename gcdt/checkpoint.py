"""Checkpoints of offline training: written by `gcdt.training`, read by it (to resume) and by
`gcdt.policies.trained` (to act), so that a policy never needs the trainer.

A checkpoint is one `torch.save`d dict (format `CHECKPOINT_FORMAT`, version
`CHECKPOINT_VERSION`) named `CHECKPOINT_NAME` in its run folder. It holds the method, task,
`train_config` and `model_config` (plain dicts), the weights, the state normalisation, and
everything else a resumed run needs (optimiser, schedule, RNG states, step, loss history).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import torch

from gcdt.errors import GcdtError
from gcdt.models import BCConfig, BCPolicyNet, DTConfig, GoalConditionedDT
from gcdt.paths import atomic_write

CHECKPOINT_FORMAT = "gcdt.checkpoint"
CHECKPOINT_VERSION = 1
CHECKPOINT_NAME = "checkpoint.pt"
#: Each trainer method's model: (config class, model class).
MODELS: dict[str, tuple[type, type[torch.nn.Module]]] = {
    "dt": (DTConfig, GoalConditionedDT),
    "bc": (BCConfig, BCPolicyNet),
}


def method_label(method: str, goal_conditioning: str) -> str:
    """How results name a method: `gcdt` (the paper's), `dt` (no goals), `dt-desired`, `bc`."""
    if method == "bc":
        return "bc"
    return {"desired+achieved": "gcdt", "none": "dt"}.get(goal_conditioning, "dt-desired")


def build_model(method: str, model_config: dict[str, Any]) -> torch.nn.Module:
    """The untrained model of `method` ("dt" or "bc") with a checkpoint's `model_config`."""
    config_class, model_class = MODELS[method]
    return model_class(config_class(**model_config))


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
