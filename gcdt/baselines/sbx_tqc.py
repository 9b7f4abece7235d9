"""SBX's TQC with its critic update's sort replaced by a mask: the `sbx` backend's algorithm.

TQC's critic target keeps the lowest `n_target_quantiles` of the critics' pooled next-state
quantiles (it drops the top 2 per critic). SBX finds them with a full sort of every row,
which XLA's CPU backend runs slowly (`python benchmarks/tqc_her.py throughput` measures the
whole step). The quantile Huber loss is a mean over (quantile, target) pairs, so the order of
the targets never matters, only which ones are kept: `keep_lowest` marks them by removing the
row maximum `n_drop` times, and the loss averages over the kept pairs.
Same targets, same loss, same gradients up to float rounding; everything else, and every
saved zip, is SBX's own.
"""

from __future__ import annotations

from functools import partial
from typing import Any

import jax
import jax.numpy as jnp
from sbx import TQC as _SbxTQC


def keep_lowest(values: jax.Array, n_keep: int) -> jax.Array:
    """Boolean mask of the `n_keep` lowest entries of each row of `values` (batch, n).

    Ties are broken by position, so exactly `n_keep` entries per row are kept and the kept
    values are those of `jnp.sort(values)[:, :n_keep]`.
    """
    n = values.shape[1]
    position = jnp.arange(n)[None, :]
    keep = jnp.ones(values.shape, dtype=bool)
    for _ in range(n - n_keep):  # n_drop is small (4 for TQC's defaults): unrolled
        remaining = jnp.where(keep, values, -jnp.inf)
        top = remaining.max(axis=1, keepdims=True)
        first_top = jnp.min(jnp.where(remaining == top, position, n), axis=1, keepdims=True)
        keep = keep & (position != first_top)
    return keep


class TQC(_SbxTQC):
    """SBX's TQC; only `update_critic` differs (see the module docstring)."""

    @staticmethod
    @partial(jax.jit, static_argnames=["n_target_quantiles"])
    def update_critic(
        n_target_quantiles: int,
        actor_state: Any,
        qf1_state: Any,
        qf2_state: Any,
        ent_coef_state: Any,
        observations: jax.Array,
        actions: jax.Array,
        next_observations: jax.Array,
        rewards: jax.Array,
        dones: jax.Array,
        discounts: jax.Array,
        key: jax.Array,
    ) -> tuple[Any, Any, jax.Array]:
        # The same random keys, split in the same order, as SBX's: same seed, same run.
        key, noise_key, dropout_key_1, dropout_key_2 = jax.random.split(key, 4)
        key, dropout_key_3, dropout_key_4 = jax.random.split(key, 3)
        dist = actor_state.apply_fn(actor_state.params, next_observations)
        next_actions = dist.sample(seed=noise_key)
        next_log_prob = dist.log_prob(next_actions)
        ent_coef = ent_coef_state.apply_fn({"params": ent_coef_state.params})

        next_quantiles = jnp.concatenate(
            [
                qf1_state.apply_fn(
                    state.target_params, next_observations, next_actions, rngs={"dropout": k}
                )
                for state, k in ((qf1_state, dropout_key_1), (qf2_state, dropout_key_2))
            ],
            axis=1,
        )
        kept = keep_lowest(next_quantiles, n_target_quantiles)[:, None, :].astype(jnp.float32)
        next_quantiles = next_quantiles - ent_coef * next_log_prob[:, None]
        targets = rewards[:, None] + (1 - dones[:, None]) * discounts[:, None] * next_quantiles
        targets = targets[:, None, :]  # (batch, 1, all): against (batch, n_quantiles, 1)
        n_pairs = observations.shape[0] * n_target_quantiles

        def quantile_huber_loss(params: Any, dropout_key: jax.Array) -> jax.Array:
            quantiles = qf1_state.apply_fn(
                params, observations, actions, rngs={"dropout": dropout_key}
            )[:, :, None]
            n_quantiles = quantiles.shape[1]
            tau = ((jnp.arange(n_quantiles, dtype=jnp.float32) + 0.5) / n_quantiles)[None, :, None]
            delta = targets - quantiles
            huber = jnp.where(jnp.abs(delta) > 1, jnp.abs(delta) - 0.5, 0.5 * delta**2)
            loss = jnp.abs(tau - (delta < 0).astype(jnp.float32)) * huber * kept
            return loss.sum() / (n_pairs * n_quantiles)  # the mean over kept pairs

        qf1_loss, grads1 = jax.value_and_grad(quantile_huber_loss)(qf1_state.params, dropout_key_3)
        qf2_loss, grads2 = jax.value_and_grad(quantile_huber_loss)(qf2_state.params, dropout_key_4)
        return (
            (qf1_state.apply_gradients(grads=grads1), qf2_state.apply_gradients(grads=grads2)),
            (qf1_loss, qf2_loss, ent_coef),
            key,
        )
