"""gcdt.data.collect against the simulator: whole episodes, exact rewards, reproducibility."""

from __future__ import annotations

import numpy as np
import pytest

from gcdt.data import collect
from gcdt.envs import episode_seed, make_env
from gcdt.errors import GcdtError
from gcdt.policies import RandomPolicy, ScriptedExpert


def _replay(ds, reward: str) -> dict[str, np.ndarray]:
    """Step one fresh env of `reward` type through the dataset's episodes and actions, in order
    (the history a single collecting env had), and record what the env itself returned."""
    env = make_env(ds.task, reward)
    out = {"reward": [], "terminated": [], "truncated": [], "success": [], "observation": []}
    try:
        for e in range(ds.n_episodes):
            obs, _ = env.reset(seed=int(ds.arrays["episode_seed"][e]))
            for action in ds.episode(e)["action"]:
                out["observation"].append(obs["observation"])
                obs, r, term, trunc, info = env.step(action)
                out["reward"].append(r)
                out["terminated"].append(term)
                out["truncated"].append(trunc)
                out["success"].append(info["is_success"])
    finally:
        env.close()
    return {k: np.asarray(v) for k, v in out.items()}


@pytest.mark.parametrize("task,policy", [("push", "random"), ("pick_and_place", "scripted")])
def test_collected_data_is_what_the_env_returned(task, policy):
    pol = RandomPolicy(task) if policy == "random" else ScriptedExpert(task)
    ds = collect(pol, task, 120, seed=3, n_envs=1, progress=False)

    # Whole episodes, the first of the run, just reaching the request.
    assert len(ds) >= 120 and len(ds) - ds.episode_lengths[-1] < 120
    stream = "random-collection" if policy == "random" else "collection"
    seeds = [episode_seed(3, j, stream) for j in range(ds.n_episodes)]
    np.testing.assert_array_equal(ds.arrays["episode_seed"], seeds)

    sparse, dense = _replay(ds, "sparse"), _replay(ds, "dense")
    np.testing.assert_array_equal(sparse["observation"], ds.arrays["observation"])
    np.testing.assert_array_equal(sparse["reward"], ds.rewards("sparse"))
    # The env computes the dense reward from its float64 goal, the dataset from the float32
    # goal it stores: equal to float32 rounding.
    np.testing.assert_allclose(dense["reward"], ds.rewards("dense"), rtol=0, atol=1e-6)
    for key in ("terminated", "truncated", "success"):
        np.testing.assert_array_equal(sparse[key], ds.arrays[key], err_msg=key)
        np.testing.assert_array_equal(dense[key], ds.arrays[key], err_msg=key)
    if policy == "scripted":
        assert ds.arrays["terminated"].sum() == ds.n_episodes  # the expert always succeeds here
    assert ds.metadata["policy"] == pol.config()
    assert ds.metadata["versions"]["panda-gym"] == "3.0.7"


def test_collection_is_bit_for_bit_reproducible():
    def run(seed, n_envs):
        return collect(
            ScriptedExpert("push"), "push", 150, seed=seed, n_envs=n_envs, progress=False
        )

    a = run(0, 2)
    assert a.equal_data(run(0, 2))
    assert not a.equal_data(run(1, 2))
    # Another process count runs the same episodes (same seeds, same initial states).
    b = run(0, 1)
    n = min(a.n_episodes, b.n_episodes)
    np.testing.assert_array_equal(a.arrays["episode_seed"][:n], b.arrays["episode_seed"][:n])
    np.testing.assert_array_equal(
        a.arrays["desired_goal"][a.offsets[:n]], b.arrays["desired_goal"][b.offsets[:n]]
    )


def test_clean_labels_record_the_experts_action_and_the_env_runs_the_noisy_one():
    """DART: with labels "clean", each state's action is the noise-free expert's action in that
    state, while the states themselves are those the noisy execution visited."""
    expert = ScriptedExpert("push", noise_std=0.2)
    clean = collect(expert, "push", 120, seed=5, labels="clean", progress=False)
    executed = collect(expert, "push", 120, seed=5, labels="executed", progress=False)
    assert clean.metadata["labels"] == "clean" and executed.metadata["labels"] == "executed"
    # The same noisy run (same seeds, same noise draws): same states, other actions.
    np.testing.assert_array_equal(clean.arrays["observation"], executed.arrays["observation"])
    assert not np.allclose(clean.actions, executed.actions)
    obs = {k: clean.arrays[k] for k in ("observation", "desired_goal", "achieved_goal")}
    noise_free = ScriptedExpert("push").predict(obs, np.zeros(len(clean), bool), np.zeros(0))
    np.testing.assert_array_equal(clean.actions, noise_free)
    # The executed actions are what the env ran: replaying them reproduces the observations.
    np.testing.assert_array_equal(_replay(executed, "sparse")["observation"], obs["observation"])


def test_bad_collection_arguments():
    with pytest.raises(GcdtError, match="unknown action labels 'noisy': expected one of"):
        collect(RandomPolicy("reach"), "reach", 10, labels="noisy")
    with pytest.raises(GcdtError, match="transitions must be a positive integer"):
        collect(RandomPolicy("reach"), "reach", 0)
    with pytest.raises(GcdtError, match="transitions must be a positive integer"):
        collect(RandomPolicy("reach"), "reach", -5)
    with pytest.raises(GcdtError, match="policy is for task 'reach', not 'push'"):
        collect(RandomPolicy("reach"), "push", 10)
    with pytest.raises(GcdtError, match="n_envs must be a positive integer"):
        collect(RandomPolicy("reach"), "reach", 10, n_envs=0)
