"""Trained models as policies: loaded from a checkpoint alone, batched over envs.

The DT keeps a rolling, left-padded K-step context per env. Each episode starts from the
target return-to-go (0 by default, as in the paper: "reach the goal with no further
penalty") divided by the return scale, and every reward the env returns is subtracted
(divided by the same scale) before the next prediction.

A policy runs on the GPU when one is present (`device="auto"`). There the DT's forward pass
over the whole K-step window is captured once per `reset` in a CUDA graph and replayed each
step: at this model's size a GPU step costs its kernel launches, not its arithmetic.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import torch

from gcdt import paper
from gcdt.checkpoint import build_model, load_checkpoint
from gcdt.device import resolve_device
from gcdt.envs import goal_state
from gcdt.errors import GcdtError
from gcdt.methods import method_label
from gcdt.models import state_columns
from gcdt.policies.base import Policy


class TrainedPolicy(Policy):
    """A DT or BC checkpoint behind the `Policy` interface."""

    def __init__(
        self,
        checkpoint: str | Path | dict[str, Any],
        task: str | None = None,
        *,
        target_return: float = paper.TARGET_RETURN,
        device: str = "auto",
    ) -> None:
        ckpt = checkpoint if isinstance(checkpoint, dict) else load_checkpoint(checkpoint)
        self.path = None if isinstance(checkpoint, dict) else str(checkpoint)
        if task is not None and task != ckpt["task"]:
            raise GcdtError(
                f"checkpoint {self.path} is for task {ckpt['task']!r}, not {task!r}: choose a "
                f"{task} checkpoint, or task {ckpt['task']}"
            )
        super().__init__(ckpt["task"])
        cfg = ckpt["train_config"]
        self.method = ckpt["method"]
        if not math.isfinite(target_return):
            raise GcdtError(
                f"target return must be a finite number (a DT's return-to-go), got {target_return}"
            )
        if self.method == "bc" and target_return != 0.0:
            raise GcdtError(f"checkpoint {self.path} is BC, which takes no target return")
        self.name = method_label(self.method, cfg["goal_conditioning"])
        self.cols = state_columns(self.task, cfg["goal_conditioning"])
        self.scale = float(cfg["return_scale"])
        self.target_return = float(target_return)
        self.device = resolve_device(device)
        try:
            self.model = build_model(self.method, ckpt["model_config"])
            self.model.load_state_dict(ckpt["model"])
        except (TypeError, RuntimeError, KeyError) as err:
            raise GcdtError(
                f"checkpoint {self.path} does not fit its model config ({err})"
            ) from None
        self.model.to(self.device).eval()
        self.mean = ckpt["state_mean"].numpy()
        self.std = ckpt["state_std"].numpy()
        self.k = ckpt["model_config"].get("context", 1)
        self.max_t = ckpt["model_config"].get("max_episode_steps", 1000) - 1
        self.train_config, self.trained_steps = cfg, ckpt["step"]

    def reset(self, n_envs: int, seed: int | None = None) -> None:
        super().reset(n_envs, seed)
        torch.manual_seed(0 if seed is None else seed)
        k, d, a = self.k, self.cols.stop, self.spec.action_dim
        self.states = torch.zeros(n_envs, k, d, device=self.device)
        self.actions = torch.zeros(n_envs, k, a, device=self.device)
        self.rtg = torch.zeros(n_envs, k, 1, device=self.device)
        self.timesteps = torch.zeros(n_envs, k, dtype=torch.long, device=self.device)
        self.mask = torch.zeros(n_envs, k, dtype=torch.bool, device=self.device)
        self.t = np.zeros(n_envs, dtype=np.int64)
        self.graph: tuple[torch.cuda.CUDAGraph, torch.Tensor] | None = None  # (graph, output)

    @torch.no_grad()
    def predict(
        self, obs: Mapping[str, np.ndarray], episode_start: np.ndarray, reward: np.ndarray
    ) -> np.ndarray:
        state = (goal_state(obs)[:, self.cols] - self.mean) / self.std
        state_t = torch.as_tensor(state, dtype=torch.float32, device=self.device)
        if self.method == "bc":
            return self.model(state_t).cpu().numpy().astype(np.float32)

        start = torch.as_tensor(np.asarray(episode_start, bool), device=self.device)
        reward_t = torch.as_tensor(reward, dtype=torch.float32, device=self.device)
        last_rtg = self.rtg[:, -1, 0] - reward_t / self.scale
        rtg = torch.where(
            start, torch.full_like(last_rtg, self.target_return / self.scale), last_rtg
        )
        self.t = np.where(episode_start, 0, self.t + 1)
        for buf in (self.states, self.actions, self.rtg, self.timesteps, self.mask):
            # A new episode forgets the old context (masked_fill: no host sync on a GPU).
            buf.masked_fill_(start.view(-1, *[1] * (buf.dim() - 1)), 0)
            buf[:] = torch.roll(buf, -1, dims=1)  # make room for the new step on the right
        self.states[:, -1] = state_t
        self.actions[:, -1] = 0.0  # placeholder: the state token comes first, it cannot see it
        self.rtg[:, -1, 0] = rtg
        self.timesteps[:, -1] = torch.as_tensor(np.minimum(self.t, self.max_t), device=self.device)
        self.mask[:, -1] = True
        action = self._act()
        self.actions[:, -1] = action
        return action.cpu().numpy().astype(np.float32)

    def _act(self) -> torch.Tensor:
        """The newest state tokens' actions `[n_envs, action_dim]` from the context buffers."""
        window = (self.states, self.actions, self.rtg, self.timesteps, self.mask)
        if self.device.type == "cpu":
            # Steps that are padding in every env hold nothing a real token may attend to:
            # leave them out (exact). Early in an episode most of the window is such padding.
            first = self.k - int(self.mask.sum(dim=1).max())
            return self.model(*(b[:, first:] for b in window), steps=slice(-1, None))[:, 0]
        if self.graph is None:  # the buffers are the graph's inputs, updated in place
            forward = lambda: self.model(*window, steps=slice(-1, None))[:, 0]  # noqa: E731
            self.graph = _capture(forward, self.device)
        graph, action = self.graph
        graph.replay()
        return action  # the graph's output buffer: `predict` copies it before the next replay

    @torch.no_grad()
    def attention(self, env: int = 0) -> np.ndarray:
        """Attention weights over env `env`'s current context, `[layers, heads, 3K, 3K]`
        (tokens R, s, a per step, oldest first; left padding included). DT only."""
        if self.method != "dt":
            raise GcdtError("only a Decision Transformer has attention to show")
        weights: list[torch.Tensor] = []
        i = slice(env, env + 1)
        self.model(
            self.states[i],
            self.actions[i],
            self.rtg[i],
            self.timesteps[i],
            self.mask[i],
            attention=weights,
        )
        return torch.cat(weights).cpu().numpy()

    def config(self) -> dict[str, Any]:
        return {
            **super().config(),
            "checkpoint": self.path,
            "method": self.method,
            "goal_conditioning": self.train_config["goal_conditioning"],
            # BC ignores rewards, so it runs under either; a DT's return-to-go needs its own.
            "reward": self.train_config["reward"] if self.method == "dt" else None,
            "trained_steps": self.trained_steps,
            "target_return": self.target_return,
        }


def _capture(
    forward: Callable[[], torch.Tensor], device: torch.device
) -> tuple[torch.cuda.CUDAGraph, torch.Tensor]:
    """`forward` captured in a CUDA graph on `device`, after warm-up runs on a side stream
    (which pick the kernels and allocate their workspaces, as capture requires); (graph, its
    output). Streams and graph belong to `device`, not to whichever GPU is current."""
    with torch.cuda.device(device):
        stream = torch.cuda.Stream()
        stream.wait_stream(torch.cuda.current_stream())
        with torch.cuda.stream(stream):
            for _ in range(2):
                forward()
        torch.cuda.current_stream().wait_stream(stream)
        graph = torch.cuda.CUDAGraph()
        with torch.cuda.graph(graph):
            output = forward()
    return graph, output
