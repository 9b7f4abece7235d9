"""The one evaluator every method is measured with (experts, GC-DT, DT, BC, TQC+HER).

Protocol (the authors' evaluation, from their code): run exactly `timesteps` env steps in total
over the vector of envs, count every episode that finished within them and drop the unfinished
tails; an episode succeeds if the success condition held at any of its steps; its return is the
sum of its rewards. Alternatively, run a fixed number of whole episodes.

Episode `j` of a run is always reset with `episode_seed(seed, j, "evaluation")` (a seed
stream no collection or training draws from: evaluation is held out) and episodes are handed to
envs in the order they free up, so a run is deterministic for a given `seed` and `n_envs`.
"""

from __future__ import annotations

import io
import time
from collections.abc import Iterator
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from gcdt import paper
from gcdt.envs import goal_distance
from gcdt.errors import GcdtError
from gcdt.paths import write_if_changed
from gcdt.policies.base import Policy
from gcdt.progress import progress_bar
from gcdt.regions import GoalRegion, check_goal
from gcdt.rollout import VectorRollout, VectorStep
from gcdt.settings import check_minimums, setting


@dataclass(frozen=True)
class EvaluationConfig:
    """How a policy is measured; the defaults are the paper's protocol. `evaluate` takes each
    field as a keyword, and `gcdt evaluate` as an option."""

    timesteps: int | None = setting(
        None, f"env steps in total (default {paper.EVAL_TIMESTEPS:,})", minimum=1
    )
    episodes: int | None = setting(None, "run this many whole episodes", minimum=1)
    n_envs: int = setting(
        1,
        "envs stepped side by side, each in a process of its own unless in_process",
        minimum=1,
        flag="--envs",
        metavar="N",
    )
    # Env processes pay only where there are idle cores to step them on; on a busy core their
    # messages cost more than they save (the grid gives each run one core).
    in_process: bool = setting(
        False,
        "step the envs one after another in this process: the same episodes, faster "
        "where the evaluation has one core",
    )
    seed: int = setting(0, "episode j is reset with episode_seed(seed, j)", minimum=0)

    def __post_init__(self) -> None:
        if self.timesteps is not None and self.episodes is not None:
            raise GcdtError("give either timesteps or episodes, not both")
        check_minimums(self, integer=(int, np.integer))

    def total_timesteps(self) -> int | None:
        """The env steps to run: `timesteps`, else the paper's budget unless `episodes`."""
        if self.timesteps is None and self.episodes is None:
            return paper.EVAL_TIMESTEPS
        return self.timesteps


_PAPER = EvaluationConfig()


@dataclass(frozen=True)
class EpisodeRecord:
    """One finished episode."""

    index: int  # position in the run's episode sequence
    seed: int  # the reset seed, `episode_seed(run_seed, index, "evaluation")`
    length: int  # steps taken
    ret: float  # sum of rewards of the evaluated reward type
    success: bool  # success condition met at any step
    final_distance: float  # ||achieved_goal - desired_goal|| after the last step


@dataclass
class EvaluationResult:
    """Per-episode records plus the summary the paper reports (mean return, success rate)."""

    task: str
    reward: str
    seed: int
    n_envs: int
    policy: dict[str, Any]
    timesteps: int  # env steps counted (= the budget in timesteps mode)
    wall_seconds: float  # everything, env start-up included
    stepping_seconds: float  # the stepping loop alone: the throughput measure
    episodes: list[EpisodeRecord] = field(default_factory=list)
    goal_region: str | None = None  # where the desired goals were drawn from (None: anywhere)

    @property
    def summary(self) -> dict[str, Any]:
        """Mean return, success rate, episode count and throughput; JSON-serialisable."""
        returns = np.array([e.ret for e in self.episodes], dtype=np.float64)
        n = len(self.episodes)
        return {
            "task": self.task,
            "reward": self.reward,
            "policy": self.policy.get("name"),
            "seed": self.seed,
            "n_envs": self.n_envs,
            "episodes": n,
            "success_rate": float(np.mean([e.success for e in self.episodes])) if n else None,
            "mean_return": float(returns.mean()) if n else None,
            "std_return": float(returns.std()) if n else None,
            "mean_length": float(np.mean([e.length for e in self.episodes])) if n else None,
            "mean_final_distance": (
                float(np.mean([e.final_distance for e in self.episodes])) if n else None
            ),
            "timesteps": self.timesteps,
            "wall_seconds": round(self.wall_seconds, 3),
            "steps_per_second": round(self.timesteps / max(self.stepping_seconds, 1e-9), 1),
        } | ({"goal_region": self.goal_region} if self.goal_region else {})

    def to_dict(self) -> dict[str, Any]:
        """Summary, policy config and every episode record (for result JSON files)."""
        return {
            "summary": self.summary,
            "policy": self.policy,
            "episodes": [asdict(e) for e in self.episodes],
        }


def evaluate(
    policy: Policy,
    task: str,
    reward: str,
    *,
    timesteps: int | None = _PAPER.timesteps,
    episodes: int | None = _PAPER.episodes,
    n_envs: int = _PAPER.n_envs,
    seed: int = _PAPER.seed,
    in_process: bool = _PAPER.in_process,
    goal_region: GoalRegion | None = None,
    progress: bool = True,
) -> EvaluationResult:
    """Run `policy` on `task` with `reward` and measure it.

    Give either `timesteps` (the paper's protocol; the default, `paper.EVAL_TIMESTEPS`) or
    `episodes` (that many whole episodes, independent of their lengths); `EvaluationConfig`
    checks them.
    `n_envs > 1` steps envs side by side, in processes of their own unless `in_process` (the
    episodes are the same either way), and the policy sees the whole batch each step. With
    `goal_region`, the envs draw their desired goals from that region only.
    """
    config = EvaluationConfig(
        timesteps=timesteps, episodes=episodes, n_envs=n_envs, seed=seed, in_process=in_process
    )
    env_kwargs = None if goal_region is None else {"goal_region": goal_region}
    rollout = VectorRollout(
        policy, task, reward, n_envs, seed, env_kwargs=env_kwargs, in_process=in_process
    )
    desc = f"evaluate {policy.name} on {task}/{reward}"
    started = time.perf_counter()
    with rollout:
        if episodes is None:
            records, counted = _fixed_steps(rollout, config.total_timesteps(), desc, progress)
        else:
            records, counted = _fixed_episodes(rollout, episodes, desc, progress)
        stepping_seconds = time.perf_counter() - rollout.stepping_started
    return EvaluationResult(
        task=rollout.task,
        reward=reward,
        seed=int(seed),
        n_envs=int(n_envs),
        policy=policy.config(),
        timesteps=int(counted),
        wall_seconds=time.perf_counter() - started,
        stepping_seconds=stepping_seconds,
        episodes=sorted(records, key=lambda e: e.index),
        goal_region=None if goal_region is None else str(goal_region),
    )


def _fixed_steps(
    rollout: VectorRollout, timesteps: int, desc: str, progress: bool
) -> tuple[list[EpisodeRecord], int]:
    """The paper's protocol: exactly `timesteps` env steps, the episodes finished within them
    (unfinished tails dropped); the records and the steps counted."""
    records: list[EpisodeRecord] = []
    bar = progress_bar(total=timesteps, unit="step", desc=desc, progress=progress, leave=False)
    with bar:
        for live, finished in _episodes(rollout, timesteps):
            records += finished
            bar.update(live)
    return records, timesteps


def _fixed_episodes(
    rollout: VectorRollout, episodes: int, desc: str, progress: bool
) -> tuple[list[EpisodeRecord], int]:
    """The run's first `episodes` episodes, however many steps they take; the records and
    the steps counted."""
    records: list[EpisodeRecord] = []
    counted, stream = 0, _episodes(rollout, None)
    bar = progress_bar(total=episodes, unit="episode", desc=desc, progress=progress, leave=False)
    with bar:
        while len(records) < episodes:
            live, finished = next(stream)
            counted += live
            kept = [e for e in finished if e.index < episodes]  # not those begun meanwhile
            records += kept
            bar.update(len(kept))
    return records, counted


def _episodes(
    rollout: VectorRollout, timesteps: int | None
) -> Iterator[tuple[int, list[EpisodeRecord]]]:
    """Step `rollout` (entered) and yield, per vector step, the env steps it counts and the
    episodes that ended in it. With `timesteps`, the stream ends after that many env steps:
    its last vector step may count only some envs' steps, and an uncounted step never
    finishes a counted episode."""
    n_envs, counted = rollout.n_envs, 0
    ep_return = np.zeros(n_envs)
    ep_length = np.zeros(n_envs, dtype=np.int64)
    ep_success = np.zeros(n_envs, dtype=bool)
    while timesteps is None or counted < timesteps:
        step = rollout.step()
        live = n_envs if timesteps is None else min(n_envs, timesteps - counted)
        counted += live
        ep_return += step.reward
        ep_length += 1
        ep_success |= step.success
        done = step.done
        done[live:] = False
        final_distance = goal_distance(
            step.next_obs["achieved_goal"], step.next_obs["desired_goal"]
        )
        finished = [
            EpisodeRecord(
                index=int(step.episode[i]),
                seed=rollout.seed_of(int(step.episode[i])),
                length=int(ep_length[i]),
                ret=float(ep_return[i]),
                success=bool(ep_success[i]),
                final_distance=float(final_distance[i]),
            )
            for i in np.flatnonzero(done)
        ]
        ep_return[done], ep_length[done], ep_success[done] = 0.0, 0, False
        yield live, finished


@dataclass(frozen=True)
class Recording:
    """One rendered episode, as `record_rollout` saw it."""

    frames: list[np.ndarray]  # [size, size, 3] uint8: the start, then after each step
    goal: np.ndarray  # the desired goal, world coordinates
    distances: np.ndarray  # achieved-to-desired goal distance at each frame, [steps + 1]
    rewards: np.ndarray  # [steps]
    success: bool  # the evaluator's rule: the success condition held at some step

    @property
    def steps(self) -> int:
        return len(self.rewards)

    @property
    def verdict(self) -> str:
        """How the episode ended, in words: what the explorer, the CLI and the figure say."""
        return "success" if self.success else "goal not reached"

    @property
    def ret(self) -> float:  # named as in `EpisodeRecord`
        return float(self.rewards.sum())

    def gif(self, fps: int = 12) -> bytes:
        """The frames as an animated GIF, looping."""
        from PIL import Image

        images = [Image.fromarray(np.asarray(f, dtype=np.uint8)) for f in self.frames]
        out = io.BytesIO()
        images[0].save(
            out,
            format="GIF",
            save_all=True,
            append_images=images[1:],
            duration=int(1000 / fps),
            loop=0,
        )
        return out.getvalue()


def record_rollout(
    policy: Policy,
    task: str,
    reward: str,
    seed: int = 0,
    *,
    path: str | Path | None = None,
    size: int = 360,
    fps: int = 12,
    goal: np.ndarray | None = None,
) -> Recording:
    """Render one episode headless (`rgb_array`) and, with `path`, save it as an animated GIF.

    The episode is the run's episode 0 for `seed`, the same one `evaluate(seed=seed)` starts
    with; `goal` replaces its desired goal (and moves the target marker) and must lie in the
    task's goal range. Returns the episode's `Recording`; afterwards a DT policy still holds
    the episode's last context (its `attention()` shows the final step).
    """
    frames: list[np.ndarray] = []
    distances: list[float] = []
    rewards: list[float] = []
    success = False

    def render(step: VectorStep | None = None) -> None:  # also the last frame, before reset
        nonlocal success
        obs = rollout.obs if step is None else step.next_obs
        frames.append(rollout.envs.render()[0])
        distances.append(float(goal_distance(obs["achieved_goal"][0], obs["desired_goal"][0])))
        if step is not None:
            rewards.append(float(step.reward[0]))
            success |= bool(step.success[0])

    size_kwargs = {"render_width": size, "render_height": size}
    rollout = VectorRollout(policy, task, reward, 1, seed, env_kwargs=size_kwargs, on_step=render)
    with rollout:
        if goal is not None:
            obs = _set_goal(rollout.envs.envs[0], np.asarray(goal, dtype=np.float64))
            rollout.obs = {k: v[None] for k, v in obs.items()}
        desired = rollout.obs["desired_goal"][0].astype(np.float64)
        render()
        while not rollout.step().done[0]:
            pass
    recording = Recording(
        frames=frames,
        goal=desired,
        distances=np.asarray(distances),
        rewards=np.asarray(rewards, dtype=np.float64),  # summed as `evaluate` sums them
        success=success,
    )
    if path is not None:
        write_if_changed(path, recording.gif(fps))  # atomic; an unchanged GIF is left untouched
    return recording


def _set_goal(env, goal: np.ndarray) -> dict[str, np.ndarray]:
    """Give a freshly reset panda-gym env another desired goal; its new observation, built
    from the robot's and the task's public getters as panda-gym's `RobotTaskEnv` builds it."""
    robot, task = env.unwrapped.robot, env.unwrapped.task
    check_goal(task, goal)
    task.goal = goal
    env.unwrapped.sim.set_base_pose("target", goal, np.array([0.0, 0.0, 0.0, 1.0]))
    return {
        "observation": np.concatenate(
            [robot.get_obs().astype(np.float32), task.get_obs().astype(np.float32)]
        ),
        "achieved_goal": task.get_achieved_goal().astype(np.float32),
        "desired_goal": task.get_goal().astype(np.float32),
    }
