"""The Goal-Conditioned Decision Transformer, its ablations, and the BC baseline.

`GoalConditionedDT` follows the authors' model, HuggingFace `DecisionTransformerModel`
(their public code): tokens (return-to-go, state, action) per step, a learned timestep embedding
added to each token, LayerNorm after the embeddings, GPT-2 blocks (pre-LayerNorm, ReLU MLP of
4x width, final LayerNorm), and the action predicted from each state token through tanh.

This file is that method, written plainly. By default `forward` runs the blocks through
`gcdt.fast_forward` instead, which computes the same numbers with less work (see there); the
reader of the method can skip it.

`goal_conditioning` chooses what the state token holds:

* `desired+achieved`: `[observation, desired_goal, achieved_goal]`, the paper's GC-DT;
* `desired`: `[observation, desired_goal]`;
* `none`: `[observation]`, the standard return-conditioned DT (our ablation).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import Literal, get_args

import torch
import torch.nn.functional as F
from torch import nn

from gcdt import fast_forward
from gcdt.envs import get_task
from gcdt.errors import GcdtError

GoalConditioning = Literal["desired+achieved", "desired", "none"]
GOAL_CONDITIONINGS: tuple[str, ...] = get_args(GoalConditioning)


def state_columns(task: str, goal_conditioning: str) -> slice:
    """Columns of the full goal-conditioned state `[obs, desired, achieved]` a model sees."""
    spec = get_task(task)
    widths = {
        "desired+achieved": spec.obs_dim + 2 * spec.goal_dim,
        "desired": spec.obs_dim + spec.goal_dim,
        "none": spec.obs_dim,
    }
    if goal_conditioning not in widths:
        raise GcdtError(
            f"unknown goal_conditioning {goal_conditioning!r}: expected one of "
            f"{', '.join(GOAL_CONDITIONINGS)}"
        )
    return slice(0, widths[goal_conditioning])


@dataclass(frozen=True)
class DTConfig:
    """The Decision Transformer's shape; defaults are the paper's."""

    state_dim: int
    action_dim: int
    context: int = 20  # K, steps of (R, s, a) the model sees
    hidden: int = 128
    layers: int = 3
    heads: int = 1
    dropout: float = 0.1  # embedding, attention and residual dropout alike
    max_episode_steps: int = 1000  # size of the timestep embedding table

    def __post_init__(self) -> None:
        if self.context < 1:
            raise GcdtError(f"context K must be >= 1, got {self.context}")
        if self.hidden % self.heads:
            raise GcdtError(f"hidden {self.hidden} is not divisible by heads {self.heads}")


class Block(nn.Module):
    """One GPT-2 block: pre-LayerNorm causal self-attention and ReLU MLP, each a residual."""

    def __init__(self, cfg: DTConfig) -> None:
        super().__init__()
        self.heads = cfg.heads
        self.ln_1 = nn.LayerNorm(cfg.hidden)
        self.qkv = nn.Linear(cfg.hidden, 3 * cfg.hidden)
        self.proj = nn.Linear(cfg.hidden, cfg.hidden)
        self.ln_2 = nn.LayerNorm(cfg.hidden)
        self.fc = nn.Linear(cfg.hidden, 4 * cfg.hidden)
        self.fc_proj = nn.Linear(4 * cfg.hidden, cfg.hidden)
        self.drop = nn.Dropout(cfg.dropout)

    def forward(
        self, x: torch.Tensor, mask: torch.Tensor, attention: list[torch.Tensor] | None = None
    ) -> torch.Tensor:
        """`x` `[batch, tokens, hidden]`; `mask` `[batch, 1, tokens, tokens]`, True where a
        query may attend to a key; a list `attention` receives the attention weights."""
        x = x + self.attend(self.ln_1(x), mask, attention)
        return x + self.mlp(self.ln_2(x))

    def attend(
        self, x: torch.Tensor, mask: torch.Tensor, attention: list[torch.Tensor] | None
    ) -> torch.Tensor:
        b, t, h = x.shape
        q, k, v = (
            z.view(b, t, self.heads, h // self.heads).transpose(1, 2)  # [batch, heads, t, width]
            for z in self.qkv(x).split(h, dim=2)
        )
        scores = (q @ k.transpose(-2, -1)) / math.sqrt(h // self.heads)
        weights = scores.masked_fill(~mask, float("-inf")).softmax(dim=-1)
        if attention is not None:
            attention.append(weights.detach())  # [batch, heads, tokens, tokens]
        y = self.drop(weights) @ v
        return self.drop(self.proj(y.transpose(1, 2).reshape(b, t, h)))

    def mlp(self, x: torch.Tensor) -> torch.Tensor:
        return self.drop(self.fc_proj(F.relu(self.fc(x))))


class GoalConditionedDT(nn.Module):
    """Decision Transformer over (return-to-go, state, action) tokens (see module docstring).

    `fast=False` runs the reference code of this file instead of `gcdt.fast_forward`."""

    def __init__(self, cfg: DTConfig, fast: bool = True) -> None:
        super().__init__()
        self.cfg, self.fast = cfg, fast
        self.embed_timestep = nn.Embedding(cfg.max_episode_steps, cfg.hidden)
        self.embed_return = nn.Linear(1, cfg.hidden)
        self.embed_state = nn.Linear(cfg.state_dim, cfg.hidden)
        self.embed_action = nn.Linear(cfg.action_dim, cfg.hidden)
        self.embed_ln = nn.LayerNorm(cfg.hidden)
        self.embed_drop = nn.Dropout(cfg.dropout)
        self.blocks = nn.ModuleList(Block(cfg) for _ in range(cfg.layers))
        self.ln_f = nn.LayerNorm(cfg.hidden)
        self.predict_action = nn.Linear(cfg.hidden, cfg.action_dim)
        self.apply(_init_weights)
        for name, p in self.named_parameters():  # GPT-2's scaled init of residual projections
            if name.endswith(("proj.weight", "fc_proj.weight")):
                nn.init.normal_(p, mean=0.0, std=0.02 / math.sqrt(2 * cfg.layers))

    def forward(
        self,
        states: torch.Tensor,  # [batch, K, state_dim], normalised
        actions: torch.Tensor,  # [batch, K, action_dim]
        returns_to_go: torch.Tensor,  # [batch, K, 1], scaled
        timesteps: torch.Tensor,  # [batch, K] int64
        mask: torch.Tensor,  # [batch, K] bool, False on left padding
        attention: list[torch.Tensor] | None = None,
        steps: slice = slice(None),
    ) -> torch.Tensor:
        """Predicted actions `[batch, K, action_dim]`, one per state token, zeros on the
        padding; only those of `steps` (e.g. `slice(-1, None)` when acting).

        Pass a list as `attention` to receive each layer's attention weights
        `[batch, heads, 3K, 3K]` (tokens R_1, s_1, a_1, R_2, ...), e.g. for the explorer.
        """
        tokens = self.embed(states, actions, returns_to_go, timesteps)
        attn_mask = attention_mask(mask)
        if self.fast and attention is None:  # the numbers of the lines below, with less work
            return fast_forward.predict_actions(self, tokens, mask, attn_mask, steps)
        x = self.embed_drop(self.embed_ln(tokens))
        for block in self.blocks:
            x = block(x, attn_mask, attention)
        state_tokens = x[:, 1::3][:, steps]  # s_1, s_2, ...: [batch, steps, hidden]
        return self.head(state_tokens) * mask[:, steps, None]

    def embed(
        self,
        states: torch.Tensor,
        actions: torch.Tensor,
        returns_to_go: torch.Tensor,
        timesteps: torch.Tensor,
    ) -> torch.Tensor:
        """The tokens R_1, s_1, a_1, R_2, ...: `[batch, 3K, hidden]`, each with its step's
        timestep embedding."""
        b, k, _ = states.shape
        time = self.embed_timestep(timesteps)  # [batch, K, hidden]
        tokens = torch.stack(
            (
                self.embed_return(returns_to_go) + time,
                self.embed_state(states) + time,
                self.embed_action(actions) + time,
            ),
            dim=2,
        )  # [batch, K, 3, hidden]
        return tokens.reshape(b, 3 * k, self.cfg.hidden)

    def head(self, x: torch.Tensor) -> torch.Tensor:
        """Actions in [-1, 1] from the last block's state tokens."""
        return torch.tanh(self.predict_action(self.ln_f(x)))


def attention_mask(mask: torch.Tensor) -> torch.Tensor:
    """Boolean `[batch, 1, 3K, 3K]`: causal, and no attention to padded keys.

    A padded query may still attend to itself, so that no row is fully masked (softmax gives
    NaN for those); padded positions' outputs are never used, real tokens never see them.
    """
    keys = mask.repeat_interleave(3, dim=1)  # [batch, 3K]
    n = keys.shape[1]
    causal = torch.ones(n, n, dtype=torch.bool, device=mask.device).tril()
    eye = torch.eye(n, dtype=torch.bool, device=mask.device)
    return (causal & keys[:, None, :] | eye)[:, None]


@dataclass(frozen=True)
class BCConfig:
    """Behavioural cloning MLP. The paper does not describe its BC; ours maps the same
    normalised state as the DT's to an action through tanh, with the DT's width and depth
    (hidden 128, 3 hidden layers) and dropout, so the two differ in the sequence model alone."""

    state_dim: int
    action_dim: int
    hidden: int = DTConfig.hidden  # the DT's defaults, declared there
    layers: int = DTConfig.layers
    dropout: float = DTConfig.dropout


class BCPolicyNet(nn.Module):
    """MLP: normalised state -> action in [-1, 1]."""

    def __init__(self, cfg: BCConfig) -> None:
        super().__init__()
        self.cfg = cfg
        dims = [cfg.state_dim] + [cfg.hidden] * cfg.layers
        layers: list[nn.Module] = []
        for d_in, d_out in itertools.pairwise(dims):
            # `nn.Dropout` with a cheaper mask on CPU.
            layers += [nn.Linear(d_in, d_out), nn.ReLU(), fast_forward.Dropout(cfg.dropout)]
        self.net = nn.Sequential(*layers, nn.Linear(cfg.hidden, cfg.action_dim), nn.Tanh())

    def forward(self, states: torch.Tensor) -> torch.Tensor:
        return self.net(states)


def _init_weights(module: nn.Module) -> None:
    """GPT-2's initialisation (as HuggingFace applies it to the Decision Transformer)."""
    if isinstance(module, nn.Linear | nn.Embedding):
        nn.init.normal_(module.weight, mean=0.0, std=0.02)
        if isinstance(module, nn.Linear) and module.bias is not None:
            nn.init.zeros_(module.bias)
    elif isinstance(module, nn.LayerNorm):
        nn.init.ones_(module.weight)
        nn.init.zeros_(module.bias)
