"""The paper's panda-gym tasks behind one factory, plus the goal-conditioned state and rewards.

Facts this module encodes (also listed in docs/architecture.md):

* panda-gym 3.0.7 re-seeds the task RNG on *every* `reset`, from OS entropy when no seed is
  given, so a seed-less reset is never reproducible. Every episode we run is therefore reset
  with an explicit seed from `episode_seed(seed, index, stream)`, one stream per purpose.
* Gymnasium sorts Dict observation keys alphabetically; the paper's state order is
  `[observation, desired_goal, achieved_goal]` and `goal_state` builds exactly that.
* Rewards are a pure function of (achieved_goal, desired_goal), so one trajectory yields both
  the sparse and the dense reward (`compute_rewards`).
* Bullet keeps contact warm-start data across resets: goals and initial positions depend only on
  the episode seed, but the physics of an episode can differ at the 1e-4 m level depending on
  what the same env simulated before. Runs are therefore reproducible for a given seed and a
  given number of envs (same history per env), which is what the evaluator guarantees.
"""

from __future__ import annotations

import contextlib
import ctypes
import functools
import os
import sys
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from typing import Any, Literal

import gymnasium as gym
import numpy as np

from gcdt.errors import GcdtError
from gcdt.regions import GoalRegion, goal_box, restrict_goals

RewardType = Literal["sparse", "dense"]
REWARDS: tuple[str, ...] = ("sparse", "dense")


@dataclass(frozen=True)
class TaskSpec:
    """Static facts of one panda-gym task (checked against the live env in the tests)."""

    name: str  # our name, e.g. "pick_and_place"
    env_name: str  # panda-gym's, e.g. "PandaPickAndPlace"
    obs_dim: int  # length of obs["observation"]
    goal_dim: int  # length of desired_goal and of achieved_goal
    action_dim: int  # 3 = end-effector displacement, 4 = plus gripper
    max_episode_steps: int
    distance_threshold: float  # success iff ||achieved - desired|| < threshold
    in_paper: bool  # one of the paper's three tasks

    @property
    def state_dim(self) -> int:
        """Length of the goal-conditioned state `[observation, desired_goal, achieved_goal]`."""
        return self.obs_dim + 2 * self.goal_dim


TASKS: dict[str, TaskSpec] = {
    t.name: t
    for t in (
        TaskSpec("reach", "PandaReach", 6, 3, 3, 50, 0.05, True),
        TaskSpec("push", "PandaPush", 18, 3, 3, 50, 0.05, True),
        TaskSpec("pick_and_place", "PandaPickAndPlace", 19, 3, 4, 50, 0.05, True),
        TaskSpec("slide", "PandaSlide", 18, 3, 3, 50, 0.05, False),
        TaskSpec("stack", "PandaStack", 31, 6, 4, 100, 0.1, False),
    )
}


def get_task(task: str) -> TaskSpec:
    """The spec of `task`, or a `GcdtError` listing the accepted names."""
    try:
        return TASKS[task]
    except (KeyError, TypeError):
        raise GcdtError(f"unknown task {task!r}: expected one of {', '.join(TASKS)}") from None


def check_reward(reward: str) -> RewardType:
    """`reward` if it is a known reward type, else a `GcdtError`."""
    if reward not in REWARDS:
        raise GcdtError(f"unknown reward {reward!r}: expected one of {', '.join(REWARDS)}")
    return reward  # type: ignore[return-value]


def env_id(task: str, reward: str) -> str:
    """The panda-gym v3 id, e.g. `env_id("push", "dense") == "PandaPushDense-v3"`."""
    suffix = "Dense" if check_reward(reward) == "dense" else ""
    return f"{get_task(task).env_name}{suffix}-v3"


# --------------------------------------------------------------------------------------------
# Construction


@contextlib.contextmanager
def _native_output_silenced(fd: int = 1) -> Iterator[None]:
    """Drop what C code writes to file descriptor `fd` (1: C stdout, 2: C stderr) meanwhile.

    pybullet prints its build time to fd 2 when its module initialises and its connection
    arguments (`argv[0]=...`) to fd 1 on every connect. Python-level redirection cannot catch
    printf from C, and a JSON line printed by the CLI must stay the last line of stdout, so the
    descriptor itself is swapped. By number, not `sys.stdout.fileno()`: in a Jupyter kernel that
    is a copy of the kernel's original stdout, while fd 1 is the pipe shown in the notebook.
    """
    stream = sys.stdout if fd == 1 else sys.stderr
    if stream is not None:
        stream.flush()  # what Python wrote before stays visible
    saved = os.dup(fd)
    try:
        with open(os.devnull, "w") as devnull:
            os.dup2(devnull.fileno(), fd)
            try:
                yield
            finally:
                ctypes.CDLL(None).fflush(None)  # flush C stdio while fd is still /dev/null
                os.dup2(saved, fd)
    finally:
        os.close(saved)


@functools.cache
def _register_panda_envs() -> None:
    with _native_output_silenced(2):  # only pybullet's module init runs here: its banner
        import pybullet  # noqa: F401
    with _native_output_silenced(1):
        import panda_gym  # noqa: F401  (registers the Panda*-v3 ids with gymnasium)


def make_env(
    task: str,
    reward: str,
    *,
    render_mode: str = "rgb_array",
    goal_region: GoalRegion | None = None,
    **kwargs,
) -> gym.Env:
    """One panda-gym env for `task` and `reward` (50-step time limit, 100 for stack).

    The default `render_mode="rgb_array"` is headless (pybullet DIRECT): `render()` returns
    frames and nothing opens a window; `"human"` opens the GUI. With `goal_region` the env
    draws its desired goals from that region only (`gcdt.regions`). Extra kwargs go to the
    panda-gym constructor (e.g. `render_width`).
    """
    eid = env_id(task, reward)
    _register_panda_envs()
    with _native_output_silenced(1):  # construction connects to pybullet; stepping is not hidden
        env = gym.make(eid, render_mode=render_mode, disable_env_checker=True, **kwargs)
    if goal_region is not None:
        try:
            restrict_goals(env.unwrapped.task, goal_region)
        except GcdtError:
            env.close()
            raise
    return env


def goal_range(task: str) -> tuple[np.ndarray, np.ndarray]:
    """The world-coordinate box `task` draws its desired goal from (low, high); a task with
    several goal positions (Stack) is refused."""
    low, high = _goal_range(get_task(task).name)
    return low.copy(), high.copy()  # the cached arrays stay as they are


@functools.cache
def _goal_range(task: str) -> tuple[np.ndarray, np.ndarray]:
    env = make_env(task, "sparse")
    try:
        return goal_box(env.unwrapped.task)
    finally:
        env.close()


def make_vec_env(
    task: str,
    reward: str,
    n_envs: int,
    *,
    in_process: bool = False,
    context: str | None = "spawn",
    **env_kwargs,
) -> gym.vector.VectorEnv:
    """`n_envs` copies of the env: one process each (`AsyncVectorEnv`), or all in this process,
    stepped one after another (`SyncVectorEnv`), for one env or with `in_process`. Both give
    the same episodes: each env is its own Bullet client either way. `env_kwargs` go to
    `make_env` (e.g. `render_width`).

    Autoreset is disabled: the caller resets finished envs itself, with explicit seeds
    (`reset(seed=[...], options={"reset_mask": done})`), because panda-gym's own seed-less
    resets are not reproducible. Processes are spawned, not forked, so that a parent holding
    torch or CUDA state never forks it into the workers.
    """
    if not isinstance(n_envs, int | np.integer) or n_envs < 1:
        raise GcdtError(f"n_envs must be a positive integer, got {n_envs!r}")
    env_id(task, reward)  # validate names in this process, before any worker starts
    factory = functools.partial(make_env, task, reward, **env_kwargs)
    mode = gym.vector.AutoresetMode.DISABLED
    if n_envs == 1 or in_process:
        return gym.vector.SyncVectorEnv([factory] * n_envs, autoreset_mode=mode)
    return gym.vector.AsyncVectorEnv([factory] * n_envs, autoreset_mode=mode, context=context)


# --------------------------------------------------------------------------------------------
# Seeds, states and rewards


#: What a run's episodes are for. Each purpose draws its reset seeds from a stream of its
#: own, so that no evaluation episode starts from an instance (goal, object position) that an
#: expert or random collection, or TQC+HER's online training, played: evaluation is held out
#: by construction, whatever seeds the runs are given.
SEED_STREAMS = {"evaluation": 1, "collection": 2, "random-collection": 3, "tqc-training": 4}


def episode_seed(seed: int, index: int, stream: str = "evaluation") -> int:
    """The reset seed of episode `index` of a run seeded with `seed`, for purpose `stream`.

    Derived through `SeedSequence` rather than `seed + index`, so that the episodes of runs
    with seeds 0, 1, 2 do not overlap, and 63 bits wide, so that the millions of episodes of
    a grid do not collide by chance (32 bits would, with a few percent probability).
    """
    if stream not in SEED_STREAMS:
        raise GcdtError(
            f"unknown seed stream {stream!r}: expected one of {', '.join(SEED_STREAMS)}"
        )
    sequence = np.random.SeedSequence(seed, spawn_key=(SEED_STREAMS[stream], index))
    return int(sequence.generate_state(1, np.uint64)[0] >> np.uint64(1))


def policy_seed(seed: int, first_episode: int, stream: str = "evaluation") -> int:
    """The seed of a policy's own randomness (noise, random actions) in a run of `seed` that
    starts at episode `first_episode`: `seed` itself for a run from episode 0, as always, and
    otherwise one drawn for that start (a spawn key of its own, unlike any episode seed's), so
    that a run started later does not replay the draws of the run from episode 0."""
    if first_episode == 0:
        return int(seed)
    key = (0, SEED_STREAMS[stream], int(first_episode))  # stream ids start at 1: no clash
    sequence = np.random.SeedSequence(seed, spawn_key=key)
    return int(sequence.generate_state(1, np.uint64)[0] >> np.uint64(1))


class SeededResets(gym.Wrapper):
    """Resets its `j`-th episode with `episode_seed(seed, offset + j * stride, stream)`,
    whatever seed the caller passes.

    For learners that reset their env themselves (SB3 resets seed-less after the first
    episode), so that their episodes, and hence their runs, are reproducible. Env `k` of `n`
    side by side takes `offset=k, stride=n`: together they play a one-env run's instances.
    """

    def __init__(
        self,
        env: gym.Env,
        seed: int,
        *,
        offset: int = 0,
        stride: int = 1,
        stream: str = "tqc-training",
    ) -> None:
        super().__init__(env)
        self.base_seed, self.episodes, self.stream = int(seed), 0, stream
        self.offset, self.stride = int(offset), int(stride)
        # The current episode's actions and last observation: enough to rebuild it.
        self.actions: list[np.ndarray] = []
        self.last_obs: Any = None

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        index = self.offset + self.episodes * self.stride
        seed = episode_seed(self.base_seed, index, self.stream)
        self.episodes += 1
        self.actions = []
        self.last_obs, info = self.env.reset(seed=seed, options=options)
        return self.last_obs, info

    def step(self, action):
        self.actions.append(np.array(action, copy=True))
        obs, reward, terminated, truncated, info = self.env.step(action)
        self.last_obs = obs
        return obs, reward, terminated, truncated, info

    def replay_state(self) -> dict[str, Any]:
        """Where this env is: its episode count and the current episode's actions."""
        return {"episodes": self.episodes, "actions": np.array(self.actions)}

    def restore_replay_state(self, state: dict[str, Any]) -> None:
        """Bring a fresh env to `replay_state()`'s point: reset with that episode's seed and
        replay its actions. The reset is exact; with an object on the table the replayed steps
        can differ slightly, by state PyBullet carries over from the env's earlier episodes
        (`gcdt.baselines.tqc_checkpoint`)."""
        if state["episodes"] == 0:
            return
        self.episodes = state["episodes"] - 1
        self.reset()
        for action in state["actions"]:
            self.step(action)


#: The keys of a panda-gym observation dict, in the paper's state order.
OBS_KEYS: tuple[str, str, str] = ("observation", "desired_goal", "achieved_goal")


def goal_state(obs: Mapping[str, np.ndarray]) -> np.ndarray:
    """The paper's state `[observation, desired_goal, achieved_goal]`, for one obs or a batch."""
    return np.concatenate([obs[k] for k in OBS_KEYS], axis=-1)


def goal_distance(achieved_goal: np.ndarray, desired_goal: np.ndarray) -> np.ndarray:
    """Euclidean distance over the last axis, in float64 as panda-gym computes it."""
    diff = np.asarray(achieved_goal, np.float64) - np.asarray(desired_goal, np.float64)
    return np.linalg.norm(diff, axis=-1)


def is_success(achieved_goal: np.ndarray, desired_goal: np.ndarray, task: str) -> np.ndarray:
    """panda-gym's success condition: distance below the task's threshold."""
    return goal_distance(achieved_goal, desired_goal) < get_task(task).distance_threshold


def compute_rewards(
    achieved_goal: np.ndarray, desired_goal: np.ndarray, task: str
) -> dict[str, np.ndarray]:
    """Both rewards of transitions ending in `achieved_goal`: sparse (-1 / 0) and dense (-d).

    Works on single transitions and on batches; float32 like the env's own rewards.
    """
    d = goal_distance(achieved_goal, desired_goal)
    sparse = -(d > get_task(task).distance_threshold).astype(np.float32)
    return {"sparse": sparse, "dense": (-d).astype(np.float32)}
