"""The Goal-Conditioned Decision Transformer, its ablations, and the BC baseline.

`GoalConditionedDT` follows the authors' model, HuggingFace `DecisionTransformerModel`
(their public code): tokens (return-to-go, state, action) per step, a learned timestep embedding
added to each token, LayerNorm after the embeddings, GPT-2 blocks (pre-LayerNorm, ReLU MLP of
4x width, final LayerNorm), and the action predicted from each state token through tanh.
Attention runs through PyTorch's scaled_dot_product_attention, except when training on CPU
(see `Dropout`). Only the outputs that are used are computed: the last block evaluates its
queries and MLP for the state tokens alone (or only the newest one when acting), which
saves nearly a fifth of the work, and the blocks compute rows for real tokens only, never
for a window's left padding (on CPU, `_Rows`); neither changes a real token's output.

`goal_conditioning` chooses what the state token holds:

* `desired+achieved`: `[observation, desired_goal, achieved_goal]`, the paper's GC-DT;
* `desired`: `[observation, desired_goal]`;
* `none`: `[observation]`, the standard return-conditioned DT (our ablation).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from gcdt.envs import get_task
from gcdt.errors import GcdtError

GoalConditioning = Literal["desired+achieved", "desired", "none"]
GOAL_CONDITIONINGS: tuple[str, ...] = ("desired+achieved", "desired", "none")


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


def _cpu_keep_scale(x: torch.Tensor, p: float) -> torch.Tensor:
    """Dropout's mask for `x` on CPU, already scaled: 0 where dropped, 1 / (1 - p) elsewhere.

    PyTorch's CPU Bernoulli draws one Mersenne-Twister number per element (~14 ns); in
    training the paper's DT spent a quarter of each step there. Here the mask comes from
    16 random bits per element drawn by NumPy's SFC64, seeded from torch's generator, so
    `torch.manual_seed` and saved RNG states still make runs reproducible. The drop
    probability is `p` rounded to a multiple of 2^-16 (0.1 -> 0.100006).
    """
    threshold = round(p * 65536)
    seed = int(torch.randint(0, 2**62, (1,)))
    n = x.numel()
    # The generator's raw 64-bit words, read as 16-bit numbers: on a little-endian CPU the
    # very bits `Generator.bytes(2 * n)` returns, at half its cost (tested).
    bits = np.random.SFC64(seed).random_raw((n + 3) // 4).view(np.uint16)[:n]
    keep = (bits >= threshold).reshape(x.shape)
    scale = np.multiply(keep, np.float32(65536 / (65536 - threshold)), dtype=np.float32)
    return torch.from_numpy(scale).to(x.dtype)


def dropout(x: torch.Tensor, p: float, training: bool) -> torch.Tensor:
    """`F.dropout`, with a cheaper mask on CPU (`_cpu_keep_scale`)."""
    if not training or p == 0.0:
        return x
    if x.device.type != "cpu":
        return F.dropout(x, p, training=True)
    return x * _cpu_keep_scale(x, p)


def add_dropout(x: torch.Tensor, y: torch.Tensor, p: float, training: bool) -> torch.Tensor:
    """`x + dropout(y)`, the residual update, where `y` is a fresh activation that may be
    overwritten: on CPU the mask is applied in place, which saves an allocation of the
    activation's size and computes the very same numbers."""
    if training and p > 0.0 and y.device.type == "cpu":
        return x + y.mul_(_cpu_keep_scale(y, p))
    return x + dropout(y, p, training)


class Dropout(nn.Module):
    """`nn.Dropout` through `dropout` (faster on CPU)."""

    def __init__(self, p: float) -> None:
        super().__init__()
        self.p = p

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return dropout(x, self.p, self.training)


def _packs(real: torch.Tensor) -> bool:
    """Whether the rows of the bool token grid `real` leave its padding out (see `_Rows`)."""
    return real.device.type == "cpu" and not bool(real.all())


class _Rows:
    """Where a block's rows of tokens `[n, width]` sit in the grid `[batch, tokens]`.

    On CPU only real tokens are rows: a training window of a short episode is mostly left
    padding (PickAndPlace's scripted episodes average 12.6 steps against K = 20), and
    everything but attention works token by token, so padding costs nothing but its
    attention columns. On a GPU every token is a row: finding the real ones (`nonzero`)
    would stall the host until the GPU's queue drains, while kernels of this size cost their
    launch, not their rows (measured on an H100, 50-step windows: a training step 7.1 ms
    with the padding's rows against 7.7-8.5 ms without; mixed on 13-step ones), and without
    host synchronisation the forward pass can be captured in a CUDA graph. `real` is the
    bool grid; without packing, rows and grid are views of each other.
    """

    def __init__(self, real: torch.Tensor) -> None:
        self.shape = real.shape
        self.index = real.reshape(-1).nonzero().squeeze(1) if _packs(real) else None

    def grid(self, rows: torch.Tensor) -> torch.Tensor:
        """`[n, width]` -> `[batch, tokens, width]`, zeros at the padding."""
        if self.index is None:
            return rows.view(*self.shape, -1)
        full = rows.new_zeros(self.shape.numel(), rows.shape[1])
        return full.index_copy(0, self.index, rows).view(*self.shape, -1)

    def rows(self, grid: torch.Tensor) -> torch.Tensor:
        """`[batch, tokens, width]` -> the real tokens' rows `[n, width]`."""
        flat = grid.reshape(-1, grid.shape[-1])
        return flat if self.index is None else flat.index_select(0, self.index)

    def numbers(self, positions: torch.Tensor, out: _Rows) -> torch.Tensor:
        """Which of this layout's rows are the rows of `out`, the layout of the tokens at
        grid `positions`: an index for `index_select` on rows, no round trip through the grid."""
        n = self.shape.numel() if self.index is None else self.index.numel()
        ids = self.grid(torch.arange(n, device=positions.device)[:, None])
        return out.rows(ids[:, positions]).squeeze(1)


class _Block(nn.Module):
    """One GPT-2 block: pre-LayerNorm attention and ReLU MLP, each with a residual."""

    def __init__(self, cfg: DTConfig) -> None:
        super().__init__()
        self.heads, self.dropout = cfg.heads, cfg.dropout
        self.ln_1 = nn.LayerNorm(cfg.hidden)
        self.qkv = nn.Linear(cfg.hidden, 3 * cfg.hidden)
        self.proj = nn.Linear(cfg.hidden, cfg.hidden)
        self.ln_2 = nn.LayerNorm(cfg.hidden)
        self.fc = nn.Linear(cfg.hidden, 4 * cfg.hidden)
        self.fc_proj = nn.Linear(4 * cfg.hidden, cfg.hidden)

    def forward(
        self,
        x: torch.Tensor,
        mask: torch.Tensor,
        layout: _Rows,
        attention: list[torch.Tensor] | None = None,
        queries: tuple[torch.Tensor, _Rows] | None = None,
    ) -> torch.Tensor:
        """`x`, rows of tokens `[n, hidden]` placed by `layout`, -> the same rows, or only
        those of `queries` (grid positions, their layout): queries and MLP for those alone,
        keys and values still from every token. `mask` is `[batch, 1, tokens, tokens]`."""
        h = x.shape[1]
        heads, width = self.heads, h // self.heads
        hx = self.ln_1(x)
        if queries is None:
            q, k, v = layout.grid(self.qkv(hx)).split(h, dim=2)
            out = layout
        else:
            positions, out = queries
            w, bias = self.qkv.weight, self.qkv.bias
            picked = layout.numbers(positions, out)
            x, mask = x.index_select(0, picked), mask[:, :, positions]
            q = out.grid(F.linear(hx.index_select(0, picked), w[:h], bias[:h]))
            k, v = layout.grid(F.linear(hx, w[h:], bias[h:])).split(h, dim=2)
        b = q.shape[0]
        q = q.view(b, -1, heads, width).transpose(1, 2)  # [batch, heads, queries, width]
        k, v = (z.view(b, -1, heads, width).transpose(1, 2) for z in (k, v))
        if attention is None and not (self.training and x.device.type == "cpu"):
            y = F.scaled_dot_product_attention(
                q, k, v, attn_mask=mask, dropout_p=self.dropout if self.training else 0.0
            )
        else:  # spelt out: to hand the weights to an inspector, and for the CPU dropout
            scores = (q @ k.transpose(-2, -1)) / math.sqrt(width)
            weights = scores.masked_fill(~mask, float("-inf")).softmax(dim=-1)
            if attention is not None:
                attention.append(weights.detach())  # [batch, heads, queries, 3K]
            y = dropout(weights, self.dropout, self.training) @ v
        drop, training = self.dropout, self.training
        # Rows from here on: a Linear's 3-D output is a view of its 2-D result, and an
        # in-place op on that view makes autograd zero-fill and copy the whole base in
        # backward (profiled: a sixth of a CPU training step).
        x = add_dropout(x, self.proj(out.rows(y.transpose(1, 2))), drop, training)
        # In place: the MLP's widest activation [rows, 4 hidden] is not written twice.
        hidden = F.relu(self.fc(self.ln_2(x)), inplace=True)
        return add_dropout(x, self.fc_proj(hidden), drop, training)


class GoalConditionedDT(nn.Module):
    """Decision Transformer over (return-to-go, state, action) tokens (see module docstring)."""

    def __init__(self, cfg: DTConfig) -> None:
        super().__init__()
        self.cfg = cfg
        self.embed_timestep = nn.Embedding(cfg.max_episode_steps, cfg.hidden)
        self.embed_return = nn.Linear(1, cfg.hidden)
        self.embed_state = nn.Linear(cfg.state_dim, cfg.hidden)
        self.embed_action = nn.Linear(cfg.action_dim, cfg.hidden)
        self.embed_ln = nn.LayerNorm(cfg.hidden)
        self.embed_drop = Dropout(cfg.dropout)
        self.blocks = nn.ModuleList(_Block(cfg) for _ in range(cfg.layers))
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
        `[batch, heads, 3K, 3K]` (tokens R_1, s_1, a_1, R_2, ...), e.g. for the explorer;
        every token's output, padding included, is then computed.
        """
        b, k, _ = states.shape
        time = self.embed_timestep(timesteps)  # [batch, K, hidden]
        tokens = torch.stack(
            (
                self.embed_return(returns_to_go) + time,
                self.embed_state(states) + time,
                self.embed_action(actions) + time,
            ),
            dim=2,
        ).reshape(b, 3 * k, self.cfg.hidden)  # R_1, s_1, a_1, R_2, ...: [batch, 3K, hidden]
        real = mask.repeat_interleave(3, dim=1)  # [batch, 3K]
        # The inspector sees every token, padding included.
        layout = _Rows(real if attention is None else torch.ones_like(real))
        x = self.embed_drop(self.embed_ln(layout.rows(tokens)))
        attn_mask = _attention_mask(mask)
        state_tokens = 3 * torch.arange(k, device=x.device)[steps] + 1
        for block in self.blocks[:-1]:
            x = block(x, attn_mask, layout, attention)
        real_queries = real[:, state_tokens]
        queries = _Rows(real_queries)
        if attention is None:  # nothing after the last block reads the R and a tokens
            x = self.blocks[-1](x, attn_mask, layout, queries=(state_tokens, queries))
        else:
            x = self.blocks[-1](x, attn_mask, layout, attention)
            x = queries.rows(layout.grid(x)[:, state_tokens])
        # From the real state tokens; zeros where the window is padded (unpacked rows, as
        # on a GPU, computed something there).
        actions = queries.grid(torch.tanh(self.predict_action(self.ln_f(x))))
        return actions if queries.index is not None else actions * real_queries[..., None]


def _attention_mask(mask: torch.Tensor) -> torch.Tensor:
    """Boolean `[batch, 1, 3K, 3K]`: causal, and no attention to padded keys.

    A padded query may still attend to itself, so that no row is fully masked (SDPA returns
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
    hidden: int = 128
    layers: int = 3
    dropout: float = 0.1


class BCPolicyNet(nn.Module):
    """MLP: normalised state -> action in [-1, 1]."""

    def __init__(self, cfg: BCConfig) -> None:
        super().__init__()
        self.cfg = cfg
        dims = [cfg.state_dim] + [cfg.hidden] * cfg.layers
        layers: list[nn.Module] = []
        for d_in, d_out in itertools.pairwise(dims):
            layers += [nn.Linear(d_in, d_out), nn.ReLU(), Dropout(cfg.dropout)]
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
