"""The interface every policy shares: experts, random, GC-DT, BC and TQC+HER alike."""

from __future__ import annotations

import abc
from collections.abc import Mapping
from typing import Any

import numpy as np

from gcdt.envs import TaskSpec, get_task


class Policy(abc.ABC):
    """A batched, possibly stateful policy for one task.

    Whoever runs it (the evaluator, the collector) calls `reset(n_envs, seed)` once before a
    run, then, every step, `predict(obs, episode_start, reward)` with

    * `obs`: the batched observation dict, arrays of shape `[n_envs, dim]`;
    * `episode_start`: bool `[n_envs]`, True where `obs` is the first of a new episode;
    * `reward`: float `[n_envs]`, the reward each env returned for the previous action
      (0 where an episode starts).

    and gets float32 actions `[n_envs, action_dim]` in `[-1, 1]`. Passing episode starts and
    rewards in is what lets stateful policies (the Decision Transformer's context window and
    return-to-go) run under the same evaluator as stateless ones, with no special cases.
    """

    #: Short name recorded with results and datasets.
    name: str = "policy"
    #: The actions the policy meant at its last `predict`, before any exploration noise it
    #: added itself; None when it added none. A collection may record these as the labels
    #: (DART's clean labels) while the env executes the noisy ones.
    intended: np.ndarray | None = None

    def __init__(self, task: str) -> None:
        self.spec: TaskSpec = get_task(task)
        self.n_envs = 0
        self.rng = np.random.default_rng()

    @property
    def task(self) -> str:
        return self.spec.name

    def reset(self, n_envs: int, seed: int | None = None) -> None:
        """Prepare for `n_envs` parallel episodes; `seed` fixes any randomness of the policy."""
        self.n_envs = n_envs
        self.rng = np.random.default_rng(seed)

    @abc.abstractmethod
    def predict(
        self,
        obs: Mapping[str, np.ndarray],
        episode_start: np.ndarray,
        reward: np.ndarray,
    ) -> np.ndarray:
        """Actions `[n_envs, action_dim]` for the batch `obs` (see the class docstring)."""

    def config(self) -> dict[str, Any]:
        """What identifies this policy in results and dataset metadata."""
        return {"name": self.name, "task": self.task}
