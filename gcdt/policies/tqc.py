"""A trained TQC+HER agent (an SB3 zip) as a policy: `gcdt evaluate --policy tqc:PATH`.

Zips of both backends load: sb3-contrib's (PyTorch weights, the policy rebuilt from them)
and SBX's (the JAX policy pickled whole). Only the policy is loaded (no replay buffer, no
env), and it acts
deterministically (the mean action), as rl-baselines3-zoo evaluates. Zips written by
`gcdt tqc train` carry the task and reward they were trained with, and are checked against
the ones asked for (the reward by the rollout, as for every trained policy); any SB3 TQC zip is
checked against the task's observation and action sizes.
Like every SB3 zip, loading one unpickles Python objects: load only zips you trust.
"""

from __future__ import annotations

import zipfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import torch

from gcdt.envs import OBS_KEYS
from gcdt.errors import GcdtError
from gcdt.policies.base import Policy


class TQCPolicy(Policy):
    """A TQC actor behind the `Policy` interface; from a zip path or a live SB3 policy."""

    name = "tqc"

    def __init__(
        self,
        model: str | Path | Any,
        task: str,
        *,
        meta: Mapping[str, Any] | None = None,
        device: str = "cpu",
        backend: str | None = None,
    ) -> None:
        super().__init__(task)
        if isinstance(model, str | Path):
            self.path: str | None = str(model)
            self.sb3_policy, meta = _load_zip(Path(model), device, backend)
        else:
            self.path, self.sb3_policy = None, model
        self.meta = dict(meta or {})
        self._check()

    def _check(self) -> None:
        where = self.path or "the TQC model"
        trained_task = self.meta.get("task")
        if trained_task is not None and trained_task != self.task:
            raise GcdtError(f"{where} was trained on task {trained_task!r}, not {self.task!r}")
        space = self.sb3_policy.observation_space
        try:
            obs_dim = space["observation"].shape[0]
            goal_dims = (space["desired_goal"].shape[0], space["achieved_goal"].shape[0])
            action_dim = self.sb3_policy.action_space.shape[0]
        except (KeyError, TypeError, AttributeError, IndexError):
            raise GcdtError(f"{where} is not a goal-conditioned (dict observation) agent") from None
        sizes = (obs_dim, *goal_dims, action_dim)
        wanted = (self.spec.obs_dim, self.spec.goal_dim, self.spec.goal_dim, self.spec.action_dim)
        if sizes != wanted:
            raise GcdtError(
                f"{where} has observation/goal/action sizes {sizes}, but {self.task} has "
                f"{wanted}: it was trained on another task"
            )

    @property
    def reward(self) -> str | None:
        """The reward type the agent was trained with, where the zip records it."""
        return self.meta.get("reward")

    @torch.no_grad()
    def predict(
        self, obs: Mapping[str, np.ndarray], episode_start: np.ndarray, reward: np.ndarray
    ) -> np.ndarray:
        batch = {key: np.asarray(obs[key], dtype=np.float32) for key in OBS_KEYS}
        action, _ = self.sb3_policy.predict(batch, deterministic=True)
        return np.asarray(action, dtype=np.float32)

    def config(self) -> dict[str, Any]:
        return {
            **super().config(),
            "path": self.path,
            "reward": self.reward,
            "trained": {k: v for k, v in self.meta.items() if k not in ("task", "reward")},
        }


def _load_zip(path: Path, device: str, backend: str | None) -> tuple[Any, dict[str, Any]]:
    """The policy of the TQC zip at `path` (of `backend`, if given), and its gcdt metadata."""
    from stable_baselines3.common.save_util import load_from_zip_file

    if not path.is_file():
        raise GcdtError(f"no TQC model at {path}: expected the .zip written by `gcdt tqc train`")
    try:
        data, params, _ = load_from_zip_file(path, device=device)
        written_by = _backend_of(data["policy_class"])
        if written_by is None:
            raise GcdtError(f"{path} holds a {data['policy_class'].__name__}, not a TQC policy")
        if backend is not None and written_by != backend:
            raise GcdtError(
                f"{path} was written by the {written_by} backend, not {backend}: load it with "
                f"backend {written_by}, or train a model with --backend {backend}"
            )
        if written_by == "sbx":  # SBX pickles its whole policy, parameters included
            policy = data["policy"]
        else:
            policy = data["policy_class"](
                data["observation_space"],
                data["action_space"],
                lambda _: 0.0,  # learning-rate schedule: the optimiser is never stepped here
                **data.get("policy_kwargs", {}),
            )
            policy.load_state_dict(params["policy"])
            policy.to(device).set_training_mode(False)
    except GcdtError:
        raise
    except ModuleNotFoundError as err:
        raise GcdtError(
            f"{path} needs the Python package {err.name!r} to load; install the project's "
            "environment (make install)"
        ) from None
    except (zipfile.BadZipFile, ValueError, KeyError, TypeError, RuntimeError, EOFError) as err:
        raise GcdtError(
            f"{path} is not a readable SB3 TQC model zip ({type(err).__name__}: {err}); "
            "pass the model.zip or best_model.zip that `gcdt tqc train` wrote"
        ) from None
    return policy, dict(data.get("gcdt") or {})


def _backend_of(policy_class: Any) -> str | None:
    """ "sb3" or "sbx" for a TQC policy class, None for anything else."""
    module = getattr(policy_class, "__module__", "")
    for backend, prefix in (("sb3", "sb3_contrib.tqc"), ("sbx", "sbx.tqc")):
        if module.startswith(prefix):
            return backend
    return None
