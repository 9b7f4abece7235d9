"""gcdt.envs: task table, factory, seeding, goal-conditioned state and reward relabelling."""

from __future__ import annotations

import multiprocessing as mp
import subprocess
import sys

import numpy as np
import pytest

from gcdt.envs import (
    TASKS,
    SeededResets,
    compute_rewards,
    env_id,
    episode_seed,
    get_task,
    goal_state,
    is_success,
    make_env,
    make_vec_env,
)
from gcdt.errors import GcdtError


@pytest.mark.parametrize("task", list(TASKS))
def test_task_spec_matches_live_env(task):
    spec = get_task(task)
    env = make_env(task, "sparse")
    try:
        space = env.observation_space
        assert space["observation"].shape == (spec.obs_dim,)
        assert space["desired_goal"].shape == (spec.goal_dim,)
        assert space["achieved_goal"].shape == (spec.goal_dim,)
        assert env.action_space.shape == (spec.action_dim,)
        assert env.spec.max_episode_steps == spec.max_episode_steps
        assert env.unwrapped.task.distance_threshold == spec.distance_threshold
    finally:
        env.close()


def test_env_ids():
    assert env_id("reach", "sparse") == "PandaReach-v3"
    assert env_id("push", "dense") == "PandaPushDense-v3"
    assert env_id("pick_and_place", "dense") == "PandaPickAndPlaceDense-v3"
    assert env_id("stack", "sparse") == "PandaStack-v3"
    assert [t for t, s in TASKS.items() if s.in_paper] == ["reach", "push", "pick_and_place"]


@pytest.mark.parametrize(
    ("task", "reward", "match"),
    [
        ("reech", "sparse", "unknown task 'reech': expected one of reach, push"),
        ("reach", "shaped", "unknown reward 'shaped': expected one of sparse, dense"),
    ],
)
def test_unknown_names_rejected(task, reward, match):
    with pytest.raises(GcdtError, match=match):
        make_env(task, reward)


def test_goal_state_order_single_and_batched():
    obs = {
        "achieved_goal": np.array([7.0, 8.0, 9.0]),
        "desired_goal": np.array([4.0, 5.0, 6.0]),
        "observation": np.array([1.0, 2.0, 3.0]),
    }
    np.testing.assert_array_equal(goal_state(obs), np.arange(1.0, 10.0))
    batch = {k: np.stack([v, 10 * v]) for k, v in obs.items()}
    out = goal_state(batch)
    assert out.shape == (2, 9)
    np.testing.assert_array_equal(out[1], 10 * np.arange(1.0, 10.0))


@pytest.mark.parametrize("task", ["reach", "push", "pick_and_place", "stack"])
def test_relabelled_rewards_equal_env_rewards(task):
    """Both reward types recomputed from goals equal what panda-gym's own envs return."""
    sparse_env, dense_env = make_env(task, "sparse"), make_env(task, "dense")
    rng = np.random.default_rng(0)
    got, want = {"sparse": [], "dense": []}, {"sparse": [], "dense": []}
    successes = []
    try:
        for episode in range(4):
            seed = episode_seed(0, episode)
            sparse_env.reset(seed=seed)
            dense_env.reset(seed=seed)
            for _ in range(25):
                action = rng.uniform(-1, 1, sparse_env.action_space.shape).astype(np.float32)
                obs, r_sparse, term, _, info = sparse_env.step(action)
                obs_d, r_dense, _, _, _ = dense_env.step(action)
                np.testing.assert_array_equal(obs["achieved_goal"], obs_d["achieved_goal"])
                rewards = compute_rewards(obs["achieved_goal"], obs["desired_goal"], task)
                got["sparse"].append(rewards["sparse"])
                got["dense"].append(rewards["dense"])
                want["sparse"].append(r_sparse)
                want["dense"].append(r_dense)
                successes.append(
                    (
                        is_success(obs["achieved_goal"], obs["desired_goal"], task),
                        info["is_success"],
                    )
                )
                if term:
                    break
    finally:
        sparse_env.close()
        dense_env.close()
    np.testing.assert_array_equal(got["sparse"], want["sparse"])
    # The env measures against its float64 goal, observations carry float32: 1e-7 apart.
    np.testing.assert_allclose(got["dense"], want["dense"], rtol=0, atol=1e-6)
    assert all(bool(a) == bool(b) for a, b in successes)
    # Batched relabelling gives the same numbers as one at a time.
    batch = compute_rewards(np.zeros((2, 3)), np.array([[0.0, 0, 0.01], [0.3, 0, 0]]), "reach")
    np.testing.assert_allclose(batch["dense"], [-0.01, -0.3], rtol=1e-6)
    np.testing.assert_array_equal(batch["sparse"], [0.0, -1.0])


def test_episode_seeds_distinct_and_stable():
    seeds = [
        episode_seed(s, j, stream)
        for s in range(3)
        for j in range(1000)
        for stream in ("evaluation", "collection", "random-collection", "tqc-training")
    ]
    # Runs with seeds 0, 1, 2 share no episode, and neither do the purposes of one seed.
    assert len(set(seeds)) == len(seeds)
    assert episode_seed(0, 5) == episode_seed(0, 5) == episode_seed(0, 5, "evaluation")
    assert all(0 <= s < 2**63 for s in seeds)  # fits a dataset's int64 episode_seed
    with pytest.raises(GcdtError, match="unknown seed stream 'train': expected one of"):
        episode_seed(0, 5, "train")


def _seeded_rollouts(task: str) -> dict[str, np.ndarray]:
    """Three seeded episodes with fixed actions in a fresh env; everything it observed."""
    env = make_env(task, "sparse")
    actions = np.random.default_rng(1).uniform(-1, 1, (20, env.action_space.shape[0]))
    starts, trajectory = [], []
    for j in range(3):
        obs, _ = env.reset(seed=episode_seed(7, j))
        starts.append(np.concatenate([obs[k] for k in sorted(obs)]))
        for a in actions:
            obs, *_ = env.step(a.astype(np.float32))
            trajectory.append(np.concatenate([obs[k] for k in sorted(obs)]))
    env.close()
    return {"starts": np.array(starts), "trajectory": np.array(trajectory)}


@pytest.mark.parametrize("task", ["push", "pick_and_place"])
def test_seeded_episodes_identical_across_processes(task):
    ctx = mp.get_context("spawn")
    with ctx.Pool(2) as pool:
        a, b = pool.map(_seeded_rollouts, [task, task])
    np.testing.assert_array_equal(a["starts"], b["starts"])
    np.testing.assert_array_equal(a["trajectory"], b["trajectory"])
    assert len(np.unique(a["starts"], axis=0)) == 3  # different seeds, different episodes


def test_initial_state_depends_only_on_seed():
    """Goals and object positions come from the seed alone, whatever the env ran before."""
    fresh, used = make_env("pick_and_place", "sparse"), make_env("pick_and_place", "sparse")
    try:
        used.reset(seed=123)
        for _ in range(30):
            used.step(used.action_space.sample())
        a, _ = fresh.reset(seed=episode_seed(3, 0))
        b, _ = used.reset(seed=episode_seed(3, 0))
        for key in a:
            np.testing.assert_array_equal(a[key], b[key])
    finally:
        fresh.close()
        used.close()


def test_vec_env_factory():
    sync = make_vec_env("reach", "dense", 1)
    try:
        assert type(sync).__name__ == "SyncVectorEnv"
        obs, _ = sync.reset(seed=[1])
        assert obs["observation"].shape == (1, 6)
    finally:
        sync.close()
    envs = make_vec_env("push", "sparse", 2)
    try:
        assert type(envs).__name__ == "AsyncVectorEnv"
        obs, _ = envs.reset(seed=[episode_seed(0, 0), episode_seed(0, 0)])
        assert obs["observation"].shape == (2, 18)
        np.testing.assert_array_equal(obs["desired_goal"][0], obs["desired_goal"][1])
    finally:
        envs.close()
    with pytest.raises(GcdtError, match="n_envs must be a positive integer"):
        make_vec_env("reach", "sparse", 0)


def test_seeded_resets_make_seedless_resets_reproducible():
    goals = []
    for _ in range(2):
        env = SeededResets(make_env("push", "sparse"), seed=7)
        try:
            goals.append([env.reset()[0]["desired_goal"] for _ in range(3)])
        finally:
            env.close()
    np.testing.assert_array_equal(goals[0], goals[1])
    assert not np.array_equal(goals[0][0], goals[0][1])  # a new goal each episode


QUIET_ENVS = """
import os, sys
# Like a Jupyter kernel: sys.stdout's fileno() is a copy of fd 1, not fd 1 where C prints.
sys.stdout = open(os.dup(1), "w")
from gcdt.envs import make_env, make_vec_env
print("before", flush=True)
env = make_env("push", "sparse")
env.reset(seed=0)
env.step(env.action_space.sample())
env.render()
env.close()
envs = make_vec_env("reach", "sparse", 2)  # sub-envs built in spawned workers
envs.reset(seed=[0, 1])
envs.close()
print("after", flush=True)
"""


def test_env_creation_prints_no_pybullet_banner():
    """pybullet's build-time banner and `argv[0]=` dump never reach the process's output,
    in this process or in vector-env workers, while Python's own output still does."""
    run = subprocess.run(
        [sys.executable, "-c", QUIET_ENVS], capture_output=True, text=True, timeout=300
    )
    assert run.returncode == 0, run.stderr
    assert run.stdout == "before\nafter\n"
    for stream in (run.stdout, run.stderr):
        assert "pybullet build time" not in stream
        assert "argv[0]" not in stream
