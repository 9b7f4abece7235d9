"""The one stepping loop behind the evaluator and the collector.

`VectorRollout` runs a policy on a vector of envs and hands out episodes in index order as
envs free up: episode `j` is always reset with `episode_seed(seed, j, stream)`. Everything that
varies between its users (what to count, what to record, when to stop) stays with them; the
loop itself, the seeding and the per-env episode bookkeeping live only here.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from gcdt.envs import check_reward, episode_seed, get_task, make_env, make_vec_env, policy_seed
from gcdt.errors import GcdtError
from gcdt.policies.base import Policy


@dataclass(frozen=True)
class VectorStep:
    """One step of every env. Arrays are `[n_envs, ...]`; obs dicts hold such arrays."""

    episode: np.ndarray  # int64, the episode index each env was running
    obs: dict[str, np.ndarray]  # the observation the action was taken in
    action: np.ndarray  # float32 [n_envs, action_dim], executed
    intended: np.ndarray  # the action before the policy's own noise (`Policy.intended`)
    reward: np.ndarray  # the env's reward (of the rollout's reward type)
    next_obs: dict[str, np.ndarray]  # the observation after the step, before any reset
    terminated: np.ndarray  # bool
    truncated: np.ndarray  # bool
    success: np.ndarray  # bool, info["is_success"] after the step

    @property
    def done(self) -> np.ndarray:
        return self.terminated | self.truncated


class VectorRollout:
    """Context manager: `with VectorRollout(policy, task, reward, n_envs, seed) as r: r.step()`.

    Each `step()` advances every env once, calls `on_step` with that step (while the envs
    still show its end: the place to render a frame), and then resets the envs whose episode
    ended, with the next episode indices in env order. The run is deterministic for a given
    `seed` and `n_envs` (each env then sees the same history; see `gcdt.envs` on Bullet's warm
    starts). `stream` is the purpose the episodes' seeds are drawn for (`SEED_STREAMS` in
    `gcdt.envs`). `env_kwargs` go to each env's constructor (e.g. `render_width`); `in_process`
    steps the envs in this process rather than one process each (`make_vec_env`). `obs`, the
    observation the next step acts in, may be replaced after a change to the envs.

    `first_episode` starts the run at that episode index, on fresh envs (a collection's later
    chunk, `gcdt.data.collect`); the policy's own randomness is then seeded for that start
    (`policy_seed`), so that it does not replay the noise of the run from episode 0.
    """

    def __init__(
        self,
        policy: Policy,
        task: str,
        reward: str,
        n_envs: int,
        seed: int,
        *,
        env_kwargs: Mapping[str, Any] | None = None,
        on_step: Callable[[VectorStep], None] | None = None,
        stream: str = "evaluation",
        in_process: bool = False,
        first_episode: int = 0,
    ) -> None:
        spec = get_task(task)
        check_reward(reward)
        if policy.task != spec.name:
            raise GcdtError(f"policy is for task {policy.task!r}, not {spec.name!r}")
        trained = policy.config().get("reward")  # trained agents know their reward type
        if trained is not None and trained != reward:
            raise GcdtError(
                f"the {policy.name} policy was trained with {trained} rewards, not {reward}: "
                f"run it with --reward {trained}"
            )
        if not isinstance(n_envs, int | np.integer) or n_envs < 1:
            raise GcdtError(f"n_envs must be a positive integer, got {n_envs!r}")
        if not isinstance(seed, int | np.integer) or seed < 0:
            raise GcdtError(f"seed must be a non-negative integer, got {seed!r}")
        if not isinstance(first_episode, int | np.integer) or first_episode < 0:
            raise GcdtError(f"first_episode must be a non-negative integer, got {first_episode!r}")
        self.policy, self.task, self.reward = policy, spec.name, reward
        self.n_envs, self.seed, self.stream = int(n_envs), int(seed), stream
        self.first_episode = int(first_episode)
        episode_seed(self.seed, 0, stream)  # an unknown stream fails here, before envs start
        self.env_kwargs, self.on_step = dict(env_kwargs or {}), on_step
        self.in_process = in_process
        if self.env_kwargs.get("goal_region") is not None:  # a region without goals fails
            make_env(self.task, reward, goal_region=self.env_kwargs["goal_region"]).close()
        self.stepping_started = 0.0  # perf_counter() once the envs are up and reset

    def __enter__(self) -> VectorRollout:
        self.envs = make_vec_env(
            self.task, self.reward, self.n_envs, in_process=self.in_process, **self.env_kwargs
        )
        try:
            self.policy.reset(self.n_envs, policy_seed(self.seed, self.first_episode, self.stream))
            self.episode = self.first_episode + np.arange(self.n_envs, dtype=np.int64)
            self.next_episode = self.first_episode + self.n_envs
            self.obs, _ = self.envs.reset(seed=[self.seed_of(j) for j in self.episode])
        except BaseException:
            self.envs.close()
            raise
        self.episode_start = np.ones(self.n_envs, dtype=bool)
        self.last_reward = np.zeros(self.n_envs, dtype=np.float32)
        self.stepping_started = time.perf_counter()
        return self

    def __exit__(self, *exc) -> None:
        self.envs.close()

    def seed_of(self, episode: int) -> int:
        """The reset seed of episode `episode` of this run."""
        return episode_seed(self.seed, int(episode), self.stream)

    def step(self) -> VectorStep:
        """Advance every env by one step (see the class docstring)."""
        obs = self.obs
        action = np.asarray(
            self.policy.predict(obs, self.episode_start, self.last_reward), dtype=np.float32
        )
        intended = self.policy.intended
        next_obs, reward, terminated, truncated, info = self.envs.step(action)
        step = VectorStep(
            episode=self.episode.copy(),
            obs=obs,
            action=action,
            intended=action if intended is None else np.asarray(intended, dtype=np.float32),
            reward=np.asarray(reward, dtype=np.float32),
            next_obs=next_obs,
            terminated=np.asarray(terminated, dtype=bool),
            truncated=np.asarray(truncated, dtype=bool),
            success=np.asarray(info["is_success"], dtype=bool),
        )
        if self.on_step is not None:
            self.on_step(step)
        done = step.done
        self.obs = next_obs
        if done.any():
            finished = np.flatnonzero(done)
            self.episode[finished] = self.next_episode + np.arange(finished.size)
            self.next_episode += finished.size
            seeds = [
                self.seed_of(j) if d else None for j, d in zip(self.episode, done, strict=True)
            ]
            # The reset returns a fresh dict; `step.next_obs` keeps the final observations.
            self.obs, _ = self.envs.reset(seed=seeds, options={"reset_mask": done})
        self.episode_start = done
        self.last_reward = np.where(done, 0.0, step.reward).astype(np.float32)
        return step
