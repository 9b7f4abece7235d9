"""Policies: one batched interface (`Policy`) for experts, random actions and trained models."""

from __future__ import annotations

from pathlib import Path

from gcdt.errors import GcdtError
from gcdt.policies.base import Policy
from gcdt.policies.random import RandomPolicy
from gcdt.policies.scripted import ScriptedExpert

POLICY_NAMES: dict[str, type[Policy]] = {"random": RandomPolicy, "scripted": ScriptedExpert}


#: Prefix of a TQC+HER agent's SB3 zip in a policy spec: `tqc:runs/reach/model.zip`.
TQC_PREFIX = "tqc:"
POLICY_SPECS = "random|scripted|tqc:ZIP|CHECKPOINT"


def make_policy(policy: str, task: str, **kwargs) -> Policy:
    """The policy `policy` names, for `task`.

    `policy` is `random`, `scripted`, `tqc:PATH` (a TQC+HER zip from `gcdt tqc train`) or the
    path of a GC-DT / DT / BC checkpoint (`gcdt train`). Extra kwargs go to the named policies.
    """
    if policy in POLICY_NAMES:
        return POLICY_NAMES[policy](task, **kwargs)
    if policy.startswith(TQC_PREFIX):
        from gcdt.policies.tqc import TQCPolicy  # imports SB3: only when needed

        return TQCPolicy(policy.removeprefix(TQC_PREFIX), task)
    path = Path(policy)
    if not path.exists():
        raise GcdtError(
            f"unknown policy {policy!r}: expected {', '.join(POLICY_NAMES)}, "
            f"{TQC_PREFIX}PATH of a TQC+HER zip, or the path of an existing checkpoint file"
        )
    return load_checkpoint_policy(path, task, **kwargs)


def load_checkpoint_policy(path: Path, task: str, **kwargs) -> Policy:
    """A trained GC-DT / DT / BC checkpoint (`gcdt train`) as a policy for `task`."""
    from gcdt.policies.trained import TrainedPolicy  # imports torch: only when needed

    return TrainedPolicy(path, task, **kwargs)


__all__ = [
    "POLICY_NAMES",
    "POLICY_SPECS",
    "TQC_PREFIX",
    "Policy",
    "RandomPolicy",
    "ScriptedExpert",
    "make_policy",
]
