"""Evaluation throughput (env steps/s) of GC-DT: `evaluate` vs the simulator and vs the
authors' loop.

    python benchmarks/evaluator_throughput.py [--task push] [--timesteps 2000] [--envs 16]
                                              [--authors-timesteps 500] [--repeats 3]
                                              [--device cpu|cuda]

Writes results/bench/evaluator_throughput_<task>.json (`_cuda.json` with `--device cuda`, where
both DT paths run their model on the GPU). Compared in one run, on one machine, each cell the
median of interleaved repeats, resets included:
* `raw_vector_<N>_envs`: the vector env of N processes stepped with random actions and
  nothing else, the ceiling for anything that steps N envs;
* `evaluate_gcdt_<N>_envs`: `gcdt.evaluation.evaluate` running a GC-DT checkpoint (the
  paper's config) on the same N envs; also with 1 env, for `--authors-timesteps` steps;
  `predict_in_loop_ms_<N>_envs` is the time its forward passes took per step inside that run;
* `evaluate_random_<N>_envs`: `evaluate` running uniform random actions, as the ceiling
  does: what the evaluator itself costs on top of the simulator;
* `authors_unbatched`: the authors' evaluation, one episode at a time on one in-process env,
  the context re-padded with `torch.cat` every step and the whole sequence run through
  HuggingFace `DecisionTransformerModel` (their model; gcdt's equivalent model when
  `transformers` is not installed), the action taken from the last position.
The DT's weights come from one training step: speed depends on the shapes, not on the
weights (both DT paths see the same untrained behaviour).
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from common import raw_vector, write_report

from gcdt.data import collect
from gcdt.envs import episode_seed, goal_state, make_env

if TYPE_CHECKING:
    import torch

# The env workers are spawned, and spawn runs this script's top level again in each of them:
# torch and the gcdt modules that load it are imported where used, or 16 workers would each
# import torch (20 s more per start of 16 envs on 2 cores, for nothing they use).


def _checkpoint(task: str, tmp: Path) -> Path:
    from gcdt.policies import make_policy
    from gcdt.training import TrainConfig, train

    data = collect(make_policy("random", task), task, 200, progress=False)
    return train(data, TrainConfig(steps=1), tmp / "dt", progress=False).checkpoint


def _authors_model(ckpt: dict, device: str) -> tuple[Callable[..., torch.Tensor], str]:
    """(forward returning action predictions [1, T, action_dim], which model it is)."""
    cfg = ckpt["model_config"]
    try:
        import transformers
    except ImportError:
        from gcdt.policies.trained import TrainedPolicy

        policy = TrainedPolicy(ckpt, device=device)
        return policy.model, "gcdt GoalConditionedDT (transformers not installed)"
    from gcdt.hf_reference import hf_actions, hf_model
    from gcdt.models import DTConfig

    hf = hf_model(DTConfig(**cfg)).to(device).eval()

    return functools.partial(
        hf_actions, hf
    ), f"transformers {transformers.__version__} DecisionTransformerModel"


def authors_unbatched(task: str, ckpt: dict, timesteps: int, device: str) -> float:
    """Steps/s of the authors' evaluation loop (HF's `get_action` recipe) on one env."""
    import torch

    with torch.no_grad():
        model, _ = _authors_model(ckpt, device)
        k, scale = ckpt["model_config"]["context"], ckpt["train_config"]["return_scale"]
        mean, std = ckpt["state_mean"].to(device), ckpt["state_std"].to(device)
        a_dim = ckpt["model_config"]["action_dim"]
        zeros = functools.partial(torch.zeros, device=device)
        with contextlib.closing(make_env(task, "sparse")) as env:
            started, steps, episode = time.perf_counter(), 0, 0
            while steps < timesteps:
                obs, _ = env.reset(seed=episode_seed(0, episode))

                def state(o):
                    return torch.as_tensor(goal_state(o), dtype=torch.float32, device=device)

                states, actions = state(obs)[None], zeros(0, a_dim)
                rtg, ts = zeros(1, 1), zeros(1, 1, dtype=torch.long)
                done = False
                while not done and steps < timesteps:
                    actions = torch.cat([actions, zeros(1, a_dim)])
                    s, a, r, t = ((states - mean) / std)[-k:], actions[-k:], rtg[0, -k:], ts[0, -k:]
                    pad = k - s.shape[0]  # left padding, rebuilt every step
                    mask = torch.cat([zeros(pad), torch.ones(s.shape[0], device=device)])[None]
                    s = torch.cat([zeros(pad, s.shape[1]), s])[None]
                    a = torch.cat([zeros(pad, a_dim), a])[None]
                    r = torch.cat([zeros(pad), r])[None, :, None]
                    t = torch.cat([zeros(pad, dtype=torch.long), t])[None]
                    action = model(s, a, r, t, mask.bool())[0, -1]
                    actions[-1] = action
                    obs, reward, terminated, truncated, _ = env.step(action.cpu().numpy())
                    states = torch.cat([states, state(obs)[None]])
                    rtg = torch.cat([rtg, (rtg[0, -1] - reward / scale).reshape(1, 1)], dim=1)
                    ts = torch.cat([ts, (ts[0, -1] + 1).reshape(1, 1)], dim=1)
                    done, steps = terminated or truncated, steps + 1
                episode += 1
            return steps / (time.perf_counter() - started)


class _Timed:
    """`policy` with the wall time of its `predict` calls summed in `seconds` (a Policy by
    duck typing: subclassing gcdt's would import torch at this script's top level)."""

    def __init__(self, policy: Any) -> None:
        self.policy, self.name, self.task, self.seconds = policy, policy.name, policy.task, 0.0

    def reset(self, n_envs: int, seed: int | None = None) -> None:
        self.policy.reset(n_envs, seed)

    def predict(self, obs, episode_start, reward) -> np.ndarray:
        began = time.perf_counter()
        action = self.policy.predict(obs, episode_start, reward)
        self.seconds += time.perf_counter() - began
        return action

    @property
    def intended(self) -> np.ndarray | None:  # the rollout records it beside the action
        return self.policy.intended

    def config(self) -> dict:
        return self.policy.config()


def predict_seconds(path: Path, task: str, n_envs: int, device: str, calls: int = 100) -> float:
    """Seconds per `predict` of the GC-DT policy on `n_envs` envs with a full K-step context:
    the time a synchronous evaluator adds to each step of the vector env."""
    from gcdt.policies.trained import TrainedPolicy

    policy = TrainedPolicy(path, task, device=device)
    policy.reset(n_envs)
    with contextlib.closing(make_env(task, "sparse")) as env:
        obs = {k: np.repeat(v[None], n_envs, 0) for k, v in env.reset(seed=0)[0].items()}
    start, reward = np.ones(n_envs, bool), np.zeros(n_envs, np.float32)
    for i in range(policy.k):  # fill the context: the steady state of an episode
        policy.predict(obs, start if i == 0 else ~start, reward)
    began = time.perf_counter()
    for _ in range(calls):
        policy.predict(obs, ~start, reward)
    return (time.perf_counter() - began) / calls


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", default="push")
    parser.add_argument("--timesteps", type=int, default=2000)
    parser.add_argument("--envs", type=int, default=16)
    parser.add_argument("--authors-timesteps", type=int, default=500)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--device", default="cpu", help="where both DT paths run their model")
    args = parser.parse_args()
    n, task, device = args.envs, args.task, args.device
    import torch

    from gcdt.checkpoint import load_checkpoint
    from gcdt.evaluation import evaluate
    from gcdt.policies import make_policy
    from gcdt.policies.trained import TrainedPolicy

    with tempfile.TemporaryDirectory() as tmp:
        path = _checkpoint(task, Path(tmp))
        ckpt = load_checkpoint(path)

        samples: dict[str, list[float]] = {f"predict_in_loop_ms_{n}_envs": []}

        def run(policy: Any, n_envs: int, timesteps: int, in_loop: str | None = None) -> float:
            """Steps/s of `evaluate`; with `in_loop`, also the policy's ms per vector step
            appended to that sample list."""
            timed = _Timed(policy)
            result = evaluate(
                timed, task, "sparse", timesteps=timesteps, n_envs=n_envs, progress=False
            )
            if in_loop is not None:
                samples[in_loop].append(1e3 * timed.seconds / -(-timesteps // n_envs))
            return result.summary["steps_per_second"]

        def gcdt(n_envs: int, timesteps: int) -> float:
            in_loop = f"predict_in_loop_ms_{n}_envs" if n_envs == n else None
            return run(TrainedPolicy(path, task, device=device), n_envs, timesteps, in_loop)

        cells: dict[str, Callable[[], float]] = {
            f"raw_vector_{n}_envs": lambda: raw_vector(task, args.timesteps, n),
            f"evaluate_random_{n}_envs": lambda: run(
                make_policy("random", task), n, args.timesteps
            ),
            f"evaluate_gcdt_{n}_envs": lambda: gcdt(n, args.timesteps),
            # As many steps as the authors' loop: one env is as slow as it, per step.
            "evaluate_gcdt_1_envs": lambda: gcdt(1, args.authors_timesteps),
            "authors_unbatched": lambda: authors_unbatched(
                task, ckpt, args.authors_timesteps, device
            ),
            f"predict_ms_{n}_envs": lambda: 1e3 * predict_seconds(path, task, n, device),
        }
        samples.update({k: [] for k in cells})
        for _ in range(args.repeats):  # interleaved: this VM's speed drifts within minutes
            for key, measure in cells.items():
                samples[key].append(measure())
        authors_model = _authors_model(ckpt, device)[1]
    rows = {k: float(np.median(v)) for k, v in samples.items()}
    ours = rows[f"evaluate_gcdt_{n}_envs"]
    rows[f"evaluate_gcdt_{n}_envs_vs_raw"] = ours / rows[f"raw_vector_{n}_envs"]
    rows[f"evaluate_random_{n}_envs_vs_raw"] = (
        rows[f"evaluate_random_{n}_envs"] / rows[f"raw_vector_{n}_envs"]
    )
    rows[f"evaluate_gcdt_{n}_envs_vs_authors"] = ours / rows["authors_unbatched"]
    # The best a synchronous evaluator can do: the envs wait while the policy runs, and on a
    # machine whose cores the env processes already fill, overlapping the two gains nothing.
    # It assumes both run as fast as alone; in the loop they evict each other's caches
    # (compare predict_in_loop_ms with predict_ms).
    bound = n / (n / rows[f"raw_vector_{n}_envs"] + rows[f"predict_ms_{n}_envs"] / 1e3)
    rows[f"bound_{n}_envs"] = bound
    rows[f"bound_{n}_envs_vs_raw"] = bound / rows[f"raw_vector_{n}_envs"]
    rows[f"bound_{n}_envs_vs_authors"] = bound / rows["authors_unbatched"]
    report = {
        "unit": "env steps per second, median of repeats; *_vs_* are ratios",
        "task": task,
        "envs": n,
        "timesteps": args.timesteps,
        "authors_timesteps": args.authors_timesteps,
        "authors_model": authors_model,
        "device": device,
        "targets": {
            f"evaluate_gcdt_{n}_envs_vs_raw": ">= 0.7",
            f"evaluate_gcdt_{n}_envs_vs_authors": ">= 4",
        },
        "torch_threads": torch.get_num_threads(),
        "results": {k: round(v, 3 if "_vs_" in k else 1) for k, v in rows.items()},
        "samples": {k: [round(x, 1) for x in v] for k, v in samples.items()},
    }
    suffix = "" if device == "cpu" else f"_{device.split(':')[0]}"
    write_report(f"evaluator_throughput_{task}{suffix}", "evaluator_throughput.py", report)


if __name__ == "__main__":
    main()
