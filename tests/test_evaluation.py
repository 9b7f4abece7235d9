"""gcdt.evaluation: the paper's counting protocol, episodes mode, determinism, rollouts."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from gcdt.envs import episode_seed, make_env
from gcdt.errors import GcdtError
from gcdt.evaluation import evaluate, record_rollout
from gcdt.policies import ScriptedExpert


def _zero_policy_lengths(count: int, seed: int = 0) -> list[int]:
    """Episode lengths of an idle arm on Reach: 1 where the goal is sampled within reach of
    the resting gripper (success at the first step), else the full 50 steps."""
    env = make_env("reach", "sparse")
    try:
        return [
            1 if env.reset(seed=episode_seed(seed, j))[1]["is_success"] else 50
            for j in range(count)
        ]
    finally:
        env.close()


def _expected_records(lengths: list[int], timesteps: int, n_envs: int) -> list[tuple[int, int]]:
    """Reference for the protocol: lockstep envs, episodes handed out in order as envs free
    up, exactly `timesteps` steps counted, unfinished tails dropped. (index, length) pairs."""
    running, left = list(range(n_envs)), [lengths[j] for j in range(n_envs)]
    next_index, counted, done = n_envs, 0, []
    while counted < timesteps:
        live = min(n_envs, timesteps - counted)
        counted += live
        for i in range(live):
            left[i] -= 1
        for i in range(n_envs):
            if left[i] == 0 and i < live:
                done.append((running[i], lengths[running[i]]))
                running[i], left[i] = next_index, lengths[next_index]
                next_index += 1
            elif left[i] == 0:
                left[i] = -1  # finished on an uncounted step: never counted
    return sorted(done)


@pytest.mark.parametrize(("timesteps", "n_envs"), [(1000, 1), (1049, 1), (1000, 2), (1000, 3)])
def test_timesteps_protocol_counts_finished_episodes_only(zero_policy, timesteps, n_envs):
    """An idle arm gives known episode lengths; the evaluator must count exactly as the
    protocol says (the budget, every finished episode, no tails)."""
    lengths = _zero_policy_lengths(200)
    assert 50 in lengths and 1 in lengths  # both kinds occur with seed 0
    result = evaluate(
        zero_policy, "reach", "sparse", timesteps=timesteps, n_envs=n_envs, progress=False
    )
    assert result.timesteps == timesteps
    got = [(e.index, e.length) for e in result.episodes]
    assert got == _expected_records(lengths, timesteps, n_envs)
    for e in result.episodes:
        assert e.success == (e.length == 1)
        assert e.ret == (0.0 if e.success else -50.0)
        assert (e.final_distance < 0.05) == e.success
    s = result.summary
    assert s["episodes"] == len(got)
    assert s["success_rate"] == pytest.approx(np.mean([e.success for e in result.episodes]))


def test_episodes_mode_with_known_outcomes(alternating_policy):
    """Each env alternates solved / idle episodes; with one env, even indices succeed."""
    result = evaluate(alternating_policy, "reach", "dense", episodes=6, progress=False)
    eps = result.episodes
    assert [e.index for e in eps] == list(range(6))
    assert [e.seed for e in eps] == [episode_seed(0, j) for j in range(6)]
    assert [e.success for e in eps] == [True, False] * 3
    assert all(e.length < 10 for e in eps[::2]) and all(e.length == 50 for e in eps[1::2])
    assert result.summary["success_rate"] == 0.5
    # Dense return of an idle episode: about 50 times the final distance (the idle arm
    # still settles by a fraction of a millimetre).
    idle = eps[1]
    assert idle.ret == pytest.approx(-50 * idle.final_distance, rel=1e-3)
    # The policy saw each step's reward: an idle episode's 49 passed-in rewards + the last.
    seen = np.concatenate(alternating_policy.rewards_seen)
    first_idle = slice(eps[0].length + 1, eps[0].length + 50)
    assert seen[eps[0].length] == 0.0  # reward is reset to 0 at an episode start
    assert seen[first_idle].sum() + seen[first_idle][-1] == pytest.approx(idle.ret, rel=1e-5)


def test_episodes_mode_two_envs_counts_exactly(alternating_policy):
    result = evaluate(alternating_policy, "reach", "sparse", episodes=7, n_envs=2, progress=False)
    assert [e.index for e in result.episodes] == list(range(7))
    # Each env alternates on its own: 0 and 1 start as solved episodes on env 0 and env 1.
    assert result.episodes[0].success and result.episodes[1].success
    assert 0.25 <= result.summary["success_rate"] <= 0.75


def test_deterministic_for_seed_and_n_envs():
    def run(seed, in_process=False):
        return evaluate(
            ScriptedExpert("push", noise_std=0.3),
            "push",
            "sparse",
            timesteps=400,
            n_envs=2,
            seed=seed,
            in_process=in_process,
            progress=False,
        ).episodes

    first, again, other = run(5), run(5), run(6)
    assert first == again
    assert first != other
    # The envs stepped in this process play exactly the episodes of the env processes.
    assert run(5, in_process=True) == first


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"timesteps": 0}, "timesteps must be a positive integer"),
        ({"episodes": -3}, "episodes must be a positive integer"),
        ({"n_envs": 0}, "n_envs must be a positive integer"),
        ({"timesteps": 10, "episodes": 10}, "either timesteps or episodes"),
        ({"seed": -1}, "seed must be a non-negative integer"),
    ],
)
def test_bad_arguments_rejected(zero_policy, kwargs, match):
    with pytest.raises(GcdtError, match=match):
        evaluate(zero_policy, "reach", "sparse", progress=False, **kwargs)


def test_policy_of_another_task_rejected(zero_policy):
    with pytest.raises(GcdtError, match="policy is for task 'reach', not 'push'"):
        evaluate(zero_policy, "push", "sparse", timesteps=10, progress=False)


def test_policy_trained_with_another_reward_rejected(zero_policy, monkeypatch):
    monkeypatch.setattr(zero_policy, "config", lambda: {"name": "zero", "reward": "dense"})
    with pytest.raises(GcdtError, match="trained with dense rewards, not sparse"):
        evaluate(zero_policy, "reach", "sparse", timesteps=10, progress=False)
    assert evaluate(zero_policy, "reach", "dense", timesteps=10, progress=False).timesteps == 10


def test_record_rollout_writes_gif(tmp_path):
    path = tmp_path / "reach.gif"
    rec = record_rollout(ScriptedExpert("reach"), "reach", "sparse", seed=0, path=path, size=64)
    frames = rec.frames
    assert len(frames) == rec.steps + 1 >= 2 and frames[0].shape == (64, 64, 3)
    assert frames[0].dtype == np.uint8 and frames[0].std() > 0  # a real picture, not blank
    gif = Image.open(path)
    assert gif.n_frames == len(frames)
    assert not list(tmp_path.glob("*.tmp"))
    # The same episode as the evaluator's episode 0: same success, return and length.
    first = evaluate(ScriptedExpert("reach"), "reach", "sparse", episodes=1, seed=0).episodes[0]
    assert rec.success == first.success and rec.steps == first.length
    assert rec.ret == pytest.approx(first.ret)
    assert rec.distances.shape == (rec.steps + 1,) and rec.distances[-1] < 0.05 < rec.distances[0]


def test_record_rollout_with_a_goal():
    """`goal` replaces the episode's desired goal: the policy sees it from the first step on,
    and the scripted expert reaches it (success ends the episode early)."""
    expert, seen = ScriptedExpert("reach"), []
    predict = expert.predict

    def watching(obs, episode_start, reward):
        seen.append(obs["desired_goal"][0].copy())
        return predict(obs, episode_start, reward)

    expert.predict = watching
    goal = np.array([0.05, -0.05, 0.15])
    rec = record_rollout(expert, "reach", "sparse", seed=0, size=32, goal=goal)
    assert len(rec.frames) == len(seen) + 1 and len(seen) < 50 and rec.success
    np.testing.assert_array_equal(np.array(seen), np.tile(goal.astype(np.float32), (len(seen), 1)))
    np.testing.assert_allclose(rec.goal, goal, atol=1e-7)
    with pytest.raises(GcdtError, match=r"a goal is 3 finite coordinates x, y, z, got \[0.0, 0"):
        record_rollout(expert, "reach", "sparse", goal=np.zeros(2))
    # Reach draws its goals from a 30 cm cube around (0, 0, 0.15): the message gives it.
    with pytest.raises(
        GcdtError,
        match=r"goal \(0.300, 0.000, 0.150\) lies outside Reach's goal range: "
        r"x \[-0.150, 0.150\], y \[-0.150, 0.150\], z \[0.000, 0.300\]",
    ):
        record_rollout(expert, "reach", "sparse", goal=np.array([0.3, 0.0, 0.15]))
