"""Where torch work runs: the one place a device name (`auto`, `cpu`, `cuda`, `cuda:N`) is read."""

from __future__ import annotations

import torch

from gcdt.errors import GcdtError


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
