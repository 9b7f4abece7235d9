"""Uniformly random actions: the paper's `random` data source."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from gcdt.policies.base import Policy


class RandomPolicy(Policy):
    """Actions drawn i.i.d. from U[-1, 1]^action_dim, reproducible through `reset(seed=...)`."""

    name = "random"

    def predict(
        self, obs: Mapping[str, np.ndarray], episode_start: np.ndarray, reward: np.ndarray
    ) -> np.ndarray:
        n = len(episode_start)
        return self.rng.uniform(-1.0, 1.0, size=(n, self.spec.action_dim)).astype(np.float32)
