"""Shared fixtures and small test-only policies with known behaviour."""

from __future__ import annotations

import numpy as np
import pytest

from gcdt.policies.base import Policy


class ZeroPolicy(Policy):
    """Never moves: on Reach every episode runs its full 50 steps (unless it starts solved)."""

    name = "zero"

    def predict(self, obs, episode_start, reward):
        return np.zeros((len(episode_start), self.spec.action_dim), np.float32)


class AlternatingPolicy(Policy):
    """Reach expert on every other episode of each env, idle on the others.

    It learns of new episodes only through `episode_start`, so the evaluator's bookkeeping is
    what makes its outcomes come out as expected.
    """

    name = "alternating"

    def reset(self, n_envs, seed=None):
        super().reset(n_envs, seed)
        self.episodes_seen = np.full(n_envs, -1)
        self.rewards_seen: list[np.ndarray] = []

    def predict(self, obs, episode_start, reward):
        self.episodes_seen += episode_start
        self.rewards_seen.append(np.array(reward))
        to_goal = obs["desired_goal"] - obs["observation"][:, :3]
        act = np.clip(to_goal / 0.05, -1, 1)
        return np.where((self.episodes_seen % 2 == 0)[:, None], act, 0.0).astype(np.float32)


@pytest.fixture
def zero_policy():
    return ZeroPolicy("reach")


@pytest.fixture
def alternating_policy():
    return AlternatingPolicy("reach")
