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


@pytest.fixture(autouse=True)
def cpu_unless_marked_cuda(request, monkeypatch):
    """Every test but those marked `cuda` sees no GPU, so that `device="auto"` means the CPU
    and exact-equality tests hold on a GPU machine too; tests/test_cuda.py covers the GPU."""
    if request.node.get_closest_marker("cuda") is None:
        import torch

        monkeypatch.setattr(torch.cuda, "is_available", lambda: False)


@pytest.fixture
def zero_policy():
    return ZeroPolicy("reach")


@pytest.fixture
def alternating_policy():
    return AlternatingPolicy("reach")


def synthetic_dataset(task: str = "push", lengths=(5, 3, 7, 4), seed: int = 0):
    """A valid Dataset built without the simulator: random states, goal-consistent rewards.

    Goals are drawn close together so that some steps succeed and both reward types vary.
    """
    from gcdt.data import from_episodes
    from gcdt.envs import compute_rewards, get_task, is_success

    spec = get_task(task)
    rng = np.random.default_rng(seed)
    episodes = []
    for e, n in enumerate(lengths):
        desired = rng.uniform(-0.1, 0.1, spec.goal_dim).astype(np.float32)
        achieved = (desired + rng.normal(0, 0.05, (n + 1, spec.goal_dim))).astype(np.float32)
        obs = rng.normal(size=(n + 1, spec.obs_dim)).astype(np.float32)
        rewards = compute_rewards(achieved[1:], np.repeat(desired[None], n, 0), task)
        success = is_success(achieved[1:], desired, task)
        terminated = np.zeros(n, bool)
        terminated[-1] = success[-1]
        episodes.append(
            {
                "observation": obs[:-1],
                "desired_goal": np.repeat(desired[None], n, 0),
                "achieved_goal": achieved[:-1],
                "action": rng.uniform(-1, 1, (n, spec.action_dim)).astype(np.float32),
                "reward_sparse": rewards["sparse"],
                "reward_dense": rewards["dense"],
                "terminated": terminated,
                "truncated": ~terminated & (np.arange(n) == n - 1),
                "success": success,
                "final_observation": obs[-1],
                "final_desired_goal": desired,
                "final_achieved_goal": achieved[-1],
                "episode_seed": 1000 * seed + e,
            }
        )
    return from_episodes(task, episodes, {"source": "synthetic", "policy": {"name": "synth"}})


@pytest.fixture
def make_dataset():
    """Factory fixture: `make_dataset(task, lengths, seed)` -> a small valid Dataset."""
    return synthetic_dataset


@pytest.fixture
def assert_usage_error(capsys):
    """`check(argv, message)`: `gcdt argv` exits 2 with one stderr line containing message."""
    from gcdt.cli import main

    def check(argv: list[str], message: str) -> None:
        capsys.readouterr()
        with pytest.raises(SystemExit) as exc:  # argparse raises it; main() returns the code
            raise SystemExit(main(argv))
        assert exc.value.code == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1, err
        assert err[0].startswith("gcdt: error: ")
        assert message in err[0], err[0]

    return check


@pytest.fixture(scope="session")
def reach_expert_data():
    """3,000 transitions of the scripted Reach expert (about 1,100 episodes)."""
    from gcdt.data import collect
    from gcdt.policies import ScriptedExpert

    return collect(ScriptedExpert("reach"), "reach", 3000, seed=0, n_envs=1, progress=False)


@pytest.fixture(scope="session")
def reach_gcdt(reach_expert_data, tmp_path_factory):
    """A GC-DT trained on it that reaches goals (test_training measures >= 90 %): 400 steps
    at K = 5, shared by the tests that need a working checkpoint."""
    from gcdt.training import TrainConfig, train

    cfg = TrainConfig(method="dt", steps=400, context=5, log_every=10, checkpoint_every=10)
    return train(reach_expert_data, cfg, tmp_path_factory.mktemp("reach_gcdt"), progress=False)


def _start_ray_cluster(node_envs: tuple[dict[str, str], ...] = (), attempts: int = 3):
    """A Ray head that runs no tasks (no CPUs, no dashboard) and one 1-CPU worker node per
    entry of `node_envs`, the extra environment its processes start with; returns the
    cluster and its worker nodes. Ray gives a starting node 30 s to register, which a loaded
    2-core machine can miss: the cluster's start is tried again, never the test's sweep."""
    import os

    from ray.cluster_utils import Cluster

    for attempt in range(attempts):
        cluster = None
        saved = dict(os.environ)
        try:
            cluster = Cluster(
                initialize_head=True, head_node_args={"num_cpus": 0, "include_dashboard": False}
            )
            nodes = []
            for env in node_envs:  # a node's processes inherit the environment it starts with
                os.environ.update(env)
                nodes.append(cluster.add_node(num_cpus=1))
            cluster.wait_for_nodes()
            return cluster, nodes
        except Exception:
            if cluster is not None:
                cluster.shutdown()
            if attempt == attempts - 1:
                raise
        finally:
            os.environ.clear()
            os.environ.update(saved)
    raise AssertionError("unreachable")


@pytest.fixture
def start_ray_cluster():
    """`_start_ray_cluster`: a head and worker nodes, retried where Ray's start times out."""
    return _start_ray_cluster
