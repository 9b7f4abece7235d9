"""gcdt.policies: the shared interface, random actions and the scripted experts."""

from __future__ import annotations

import numpy as np
import pytest

from gcdt.envs import make_vec_env
from gcdt.errors import GcdtError
from gcdt.evaluation import evaluate
from gcdt.policies import RandomPolicy, ScriptedExpert, make_policy


def _batch(task: str, n: int = 3) -> dict[str, np.ndarray]:
    envs = make_vec_env(task, "sparse", 1)
    try:
        obs, _ = envs.reset(seed=[0])
    finally:
        envs.close()
    return {k: np.repeat(v, n, axis=0) for k, v in obs.items()}


def test_random_policy_shapes_range_and_seed():
    policy = RandomPolicy("pick_and_place")
    obs, start, reward = _batch("pick_and_place"), np.ones(3, bool), np.zeros(3)
    policy.reset(3, seed=4)
    a = policy.predict(obs, start, reward)
    assert a.shape == (3, 4) and a.dtype == np.float32
    assert np.all(np.abs(a) <= 1)
    policy.reset(3, seed=4)
    np.testing.assert_array_equal(policy.predict(obs, start, reward), a)
    assert not np.allclose(a[0], a[1])  # envs get independent actions


@pytest.mark.parametrize(("task", "dim"), [("reach", 3), ("push", 3), ("pick_and_place", 4)])
def test_scripted_expert_shapes_and_noise(task, dim):
    obs, start, reward = _batch(task), np.ones(3, bool), np.zeros(3)
    clean = ScriptedExpert(task)
    clean.reset(3, seed=0)
    a = clean.predict(obs, start, reward)
    assert a.shape == (3, dim) and a.dtype == np.float32
    np.testing.assert_array_equal(a[0], a[1])  # deterministic without noise
    noisy = ScriptedExpert(task, noise_std=0.2)
    noisy.reset(3, seed=0)
    b = noisy.predict(obs, start, reward)
    assert np.all(np.abs(b) <= 1) and not np.allclose(a, b)
    assert noisy.config() == {"name": "scripted", "task": task, "noise_std": 0.2}


def test_scripted_expert_rejects_uncovered_task_and_bad_noise():
    with pytest.raises(GcdtError, match="no scripted expert for task 'slide': scripted experts"):
        ScriptedExpert("slide")
    with pytest.raises(GcdtError, match="noise_std must be >= 0"):
        ScriptedExpert("reach", noise_std=-0.1)


def test_make_policy_names_and_paths(tmp_path):
    assert isinstance(make_policy("random", "push"), RandomPolicy)
    assert isinstance(make_policy("scripted", "push"), ScriptedExpert)
    with pytest.raises(GcdtError, match="unknown policy 'expert': expected random, scripted"):
        make_policy("expert", "push")
    with pytest.raises(GcdtError, match="unknown task"):
        make_policy("random", "pushh")


# The experts stand in for the paper's TQC experts: they must solve the tasks, and fast
# (offline learners copy the speed of their data), measured through the evaluator on 200
# seeded episodes. The sparse return is minus the steps taken before success.
@pytest.mark.slow
@pytest.mark.parametrize(
    ("task", "minimum", "slowest"),
    [("reach", 1.0, -2.2), ("push", 0.97, -13.0), ("pick_and_place", 0.97, -9.5)],
)
def test_scripted_expert_success_rate(task, minimum, slowest):
    result = evaluate(
        ScriptedExpert(task), task, "sparse", episodes=200, n_envs=2, seed=0, progress=False
    )
    summary = result.summary
    assert summary["episodes"] == 200
    assert summary["success_rate"] >= minimum, summary
    assert summary["mean_return"] >= slowest, summary
    # Random actions almost never solve the manipulation tasks: the bar above means something.
    if task != "reach":
        rand = evaluate(RandomPolicy(task), task, "sparse", episodes=20, seed=0, progress=False)
        assert rand.summary["success_rate"] <= 0.3
