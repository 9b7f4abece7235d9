"""Policies: one batched interface (`Policy`) for experts, random actions and trained models."""

from __future__ import annotations

from pathlib import Path

from gcdt.errors import GcdtError
from gcdt.policies.base import Policy
from gcdt.policies.random import RandomPolicy
from gcdt.policies.scripted import ScriptedExpert

POLICY_NAMES: dict[str, type[Policy]] = {"random": RandomPolicy, "scripted": ScriptedExpert}


def make_policy(policy: str, task: str, **kwargs) -> Policy:
    """A policy by name (`random`, `scripted`) or from a checkpoint path, for `task`."""
    if policy in POLICY_NAMES:
        return POLICY_NAMES[policy](task, **kwargs)
    path = Path(policy)
    if not path.exists():
        raise GcdtError(
            f"unknown policy {policy!r}: expected {', '.join(POLICY_NAMES)} "
            "or the path of an existing checkpoint file"
        )
    return load_checkpoint_policy(path, task)


def load_checkpoint_policy(path: Path, task: str) -> Policy:
    """A trained GC-DT / DT / BC checkpoint (`gcdt train`) as a policy for `task`."""
    from gcdt.policies.trained import TrainedPolicy  # imports torch: only when needed

    return TrainedPolicy(path, task)


__all__ = ["POLICY_NAMES", "Policy", "RandomPolicy", "ScriptedExpert", "make_policy"]
