"""The models' forward pass, fast: the numbers of `gcdt.models`' reference code, less work.

`gcdt.models` holds the method, written plainly; this module only makes it cheaper, and
`GoalConditionedDT.forward` hands its transformer to `predict_actions` here unless asked for
the reference path (`fast=False`, or attention weights to inspect). Tests hold the two paths
to the same outputs and gradients. What it saves:

* Only the outputs that are used: the last block evaluates its queries and MLP for the state
  tokens alone (or only the newest one when acting), nearly a fifth of the work.
* On CPU, no rows for a window's left padding (`_Rows`); neither changes a real token's output.
* On CPU, a dropout mask from NumPy's SFC64 instead of PyTorch's Mersenne-Twister Bernoulli
  (`_cpu_keep_scale`), applied in place on the residual updates (`add_dropout`), with attention
  spelt out so that its dropout draws that mask too; elsewhere, scaled_dot_product_attention.
"""

from __future__ import annotations

import math

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

# Models come in as plain modules: `gcdt.models` imports this file, never the reverse.


def _cpu_keep_scale(x: torch.Tensor, p: float) -> torch.Tensor:
    """Dropout's mask for `x` on CPU, already scaled: 0 where dropped, 1 / (1 - p) elsewhere.

    PyTorch's CPU Bernoulli draws one Mersenne-Twister number per element, a large share of
    a training step of the paper's DT. Here the mask comes from 16 random bits per element
    drawn by NumPy's SFC64, seeded from torch's generator, so `torch.manual_seed` and saved
    RNG states still make runs reproducible. The drop
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
    padding (PickAndPlace's scripted episodes are shorter than K = 20), and everything but
    attention works token by token, so padding costs nothing but its attention columns. On a
    GPU every token is a row: finding the real ones (`nonzero`) would stall the host until
    the GPU's queue drains, while kernels of this size cost their launch, not their rows (on
    an H100, keeping the padding's rows was faster on long windows, about even on short
    ones), and without host synchronisation the forward pass can be captured in a CUDA
    graph. `real` is the bool grid; without packing, rows and grid are views of each other.
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


def predict_actions(
    model: nn.Module,
    tokens: torch.Tensor,
    mask: torch.Tensor,
    attn_mask: torch.Tensor,
    steps: slice,
) -> torch.Tensor:
    """What `model.forward` returns (`model`: a `gcdt.models.GoalConditionedDT`), from its
    embedded `tokens` `[batch, 3K, hidden]` on: the actions `[batch, len(steps), action_dim]`
    of the state tokens of `steps`, zeros on the padding. `mask` is `[batch, K]`, `attn_mask`
    `[batch, 1, 3K, 3K]`."""
    k = tokens.shape[1] // 3
    real = mask.repeat_interleave(3, dim=1)  # [batch, 3K]
    layout = _Rows(real)
    x = dropout(model.embed_ln(layout.rows(tokens)), model.embed_drop.p, model.training)
    state_tokens = 3 * torch.arange(k, device=x.device)[steps] + 1
    for block in model.blocks[:-1]:
        x = _block(block, x, attn_mask, layout)
    real_queries = real[:, state_tokens]
    queries = _Rows(real_queries)
    # Nothing after the last block reads the R and a tokens.
    x = _block(model.blocks[-1], x, attn_mask, layout, queries=(state_tokens, queries))
    # From the real state tokens; zeros where the window is padded (unpacked rows, as on a
    # GPU, computed something there).
    actions = queries.grid(model.head(x))
    return actions if queries.index is not None else actions * real_queries[..., None]


def _block(
    block: nn.Module,
    x: torch.Tensor,
    mask: torch.Tensor,
    layout: _Rows,
    queries: tuple[torch.Tensor, _Rows] | None = None,
) -> torch.Tensor:
    """`block(x)` (`block`: a `gcdt.models.Block`): `x`, rows of tokens `[n, hidden]` placed by
    `layout`, -> the same rows, or only those of `queries` (grid positions, their layout):
    queries and MLP for those alone, keys and values still from every token. `mask` is
    `[batch, 1, tokens, tokens]`."""
    h = x.shape[1]
    heads, width = block.heads, h // block.heads
    drop, training = block.drop.p, block.training
    hx = block.ln_1(x)
    if queries is None:
        q, k, v = layout.grid(block.qkv(hx)).split(h, dim=2)
        out = layout
    else:
        positions, out = queries
        w, bias = block.qkv.weight, block.qkv.bias
        picked = layout.numbers(positions, out)
        x, mask = x.index_select(0, picked), mask[:, :, positions]
        q = out.grid(F.linear(hx.index_select(0, picked), w[:h], bias[:h]))
        k, v = layout.grid(F.linear(hx, w[h:], bias[h:])).split(h, dim=2)
    b = q.shape[0]
    q = q.view(b, -1, heads, width).transpose(1, 2)  # [batch, heads, queries, width]
    k, v = (z.view(b, -1, heads, width).transpose(1, 2) for z in (k, v))
    if not (training and x.device.type == "cpu"):
        y = F.scaled_dot_product_attention(
            q, k, v, attn_mask=mask, dropout_p=drop if training else 0.0
        )
    else:  # spelt out, for the CPU dropout
        scores = (q @ k.transpose(-2, -1)) / math.sqrt(width)
        weights = scores.masked_fill(~mask, float("-inf")).softmax(dim=-1)
        y = dropout(weights, drop, training) @ v
    # Rows from here on: a Linear's 3-D output is a view of its 2-D result, and an in-place
    # op on that view makes autograd zero-fill and copy the whole base in backward
    # (profiled: a sixth of a CPU training step).
    y = y.transpose(1, 2).reshape(b, -1, h)  # [batch, queries, hidden], a view for one head
    x = add_dropout(x, block.proj(out.rows(y)), drop, training)
    # In place: the MLP's widest activation [rows, 4 hidden] is not written twice.
    hidden = F.relu(block.fc(block.ln_2(x)), inplace=True)
    return add_dropout(x, block.fc_proj(hidden), drop, training)
