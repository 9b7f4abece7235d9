"""gcdt.models: shapes, causality, left padding, goal conditioning; and the seam's contract:
`gcdt.fast_forward`, the default path, computes what the reference code of `gcdt.models`
computes (`GoalConditionedDT(cfg, fast=False)`)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from gcdt import fast_forward
from gcdt.errors import GcdtError
from gcdt.fast_forward import _cpu_keep_scale, add_dropout, dropout
from gcdt.models import BCConfig, BCPolicyNet, DTConfig, GoalConditionedDT, state_columns


def _inputs(b=3, k=6, d=24, a=3, seed=0):
    g = torch.Generator().manual_seed(seed)
    return {
        "states": torch.randn(b, k, d, generator=g),
        "actions": torch.rand(b, k, a, generator=g) * 2 - 1,
        "returns_to_go": -torch.rand(b, k, 1, generator=g),
        "timesteps": torch.arange(k).repeat(b, 1),
        "mask": torch.ones(b, k, dtype=torch.bool),
    }


@pytest.fixture(params=[True, False], ids=["fast", "reference"])
def model(request):
    torch.manual_seed(0)
    return GoalConditionedDT(DTConfig(state_dim=24, action_dim=3, context=6), request.param).eval()


def _reference(net: GoalConditionedDT) -> GoalConditionedDT:
    """`net`'s weights and mode, on the reference path of `gcdt.models`."""
    ref = GoalConditionedDT(net.cfg, fast=False).train(net.training)
    ref.load_state_dict(net.state_dict())
    return ref


def test_shapes_and_range(model):
    out = model(**_inputs())
    assert out.shape == (3, 6, 3)
    assert out.abs().max() <= 1.0  # tanh head
    bc = BCPolicyNet(BCConfig(state_dim=24, action_dim=4)).eval()
    assert bc(torch.randn(5, 24)).shape == (5, 4)
    n_params = sum(p.numel() for p in model.parameters())
    assert 500_000 < n_params < 800_000  # 3 layers of hidden 128 + embeddings (paper config)


def test_causal_future_tokens_do_not_change_the_past(model):
    x = _inputs()
    base = model(**x)
    t = 2
    changed = {k: v.clone() for k, v in x.items()}
    changed["states"][:, t + 1 :] += 5.0
    changed["actions"][:, t:] = -changed["actions"][:, t:]  # a_t comes after s_t
    changed["returns_to_go"][:, t + 1 :] -= 3.0
    out = model(**changed)
    torch.testing.assert_close(out[:, : t + 1], base[:, : t + 1], rtol=0, atol=1e-6)
    assert not torch.allclose(out[:, t + 1 :], base[:, t + 1 :])


def test_left_padding_does_not_change_real_predictions(model):
    full = _inputs(k=6)
    real = 4  # the last 4 positions are real, the first 2 padding
    short = {k: v[:, -real:].clone() for k, v in full.items()}
    short["timesteps"] = torch.arange(real).repeat(3, 1)
    padded = {k: v.clone() for k, v in full.items()}
    padded["timesteps"][:, -real:] = short["timesteps"]
    padded["mask"][:, :2] = False
    out_short = model(**short)
    out_padded = model(**padded)
    torch.testing.assert_close(out_padded[:, -real:], out_short, rtol=0, atol=1e-5)
    # Whatever the padding holds makes no difference either.
    padded["states"][:, :2] = 100.0
    padded["returns_to_go"][:, :2] = 7.0
    torch.testing.assert_close(model(**padded)[:, -real:], out_short, rtol=0, atol=1e-5)
    assert torch.isfinite(model(**padded)).all()  # fully padded rows are not NaN


def test_goal_conditioning_columns_and_bad_config():
    assert state_columns("push", "desired+achieved") == slice(0, 24)
    assert state_columns("push", "desired") == slice(0, 21)
    assert state_columns("push", "none") == slice(0, 18)
    with pytest.raises(GcdtError, match="unknown goal_conditioning 'both'"):
        state_columns("push", "both")
    with pytest.raises(GcdtError, match="context K must be >= 1"):
        DTConfig(state_dim=6, action_dim=3, context=0)


def test_state_dict_keys_are_those_of_checkpoints_and_the_hf_parity_test(model):
    def linear(name):
        return [f"{name}.weight", f"{name}.bias"]

    parts = ("ln_1", "qkv", "proj", "ln_2", "fc", "fc_proj")
    expected = [
        "embed_timestep.weight",
        *(
            key
            for m in ("embed_return", "embed_state", "embed_action", "embed_ln")
            for key in linear(m)
        ),
        *(key for i in range(3) for m in parts for key in linear(f"blocks.{i}.{m}")),
        *linear("ln_f"),
        *linear("predict_action"),
    ]
    assert list(model.state_dict()) == expected


def test_attention_weights_come_from_the_reference_path_and_match_the_fast_path(model):
    inputs = _inputs()
    inputs["mask"][0, :2] = False  # a left-padded window
    attention: list[torch.Tensor] = []
    with torch.no_grad():
        fast = model(**inputs)
        spelt_out = model(**inputs, attention=attention)  # the reference path, on either model
    torch.testing.assert_close(spelt_out, fast, atol=1e-5, rtol=1e-5)
    assert len(attention) == 3 and attention[0].shape == (3, 1, 18, 18)
    torch.testing.assert_close(attention[0].sum(-1), torch.ones(3, 1, 18))
    assert attention[0][0, 0, 6:, :6].abs().max() == 0  # real tokens never see padding
    assert torch.triu(attention[1][1, 0], diagonal=1).abs().max() == 0  # causal


def test_only_the_requested_state_tokens_are_computed(model):
    inputs = _inputs()
    inputs["mask"][1, :3] = False
    with torch.no_grad():
        full = _reference(model)(**inputs)  # every token computed
        pruned = model(**inputs)  # fast: the last block evaluates state tokens only
        last = model(**inputs, steps=slice(-1, None))
        last_reference = _reference(model)(**inputs, steps=slice(-1, None))
    torch.testing.assert_close(pruned, full, atol=1e-5, rtol=1e-5)
    assert last.shape == last_reference.shape == (3, 1, 3)
    torch.testing.assert_close(last, full[:, -1:], atol=1e-5, rtol=1e-5)
    torch.testing.assert_close(last_reference, full[:, -1:], atol=1e-5, rtol=1e-5)


@pytest.mark.parametrize("heads", [1, 2])
@pytest.mark.parametrize("train", [True, False], ids=["train", "eval"])
def test_fast_path_equals_the_reference_outputs_and_gradients(monkeypatch, heads, train):
    """The seam's contract, dropout off. On CPU the fast path skips the padding's rows (and
    in training spells attention out); on a GPU it computes them (as here with `_packs` off);
    the reference path computes every token. The masked loss and its gradients must agree,
    and padded outputs are zeros on every path."""
    torch.manual_seed(0)
    cfg = DTConfig(state_dim=24, action_dim=3, context=6, heads=heads, dropout=0.0)
    net = GoalConditionedDT(cfg).train(train)
    reference = _reference(net)
    inputs = _inputs(b=4)
    inputs["mask"][0, :2] = False
    inputs["mask"][2, :5] = False  # one real step
    mask = inputs["mask"]
    results = []
    for path in ("packed", "unpacked", "reference"):
        if path == "unpacked":
            monkeypatch.setattr(fast_forward, "_packs", lambda real: False)
        model = reference if path == "reference" else net
        model.zero_grad()
        out = model(**inputs)
        torch.mean((out - inputs["actions"])[mask] ** 2).backward()
        grads = {n: p.grad.clone() for n, p in model.named_parameters() if p.grad is not None}
        results.append((out.detach(), grads))
        monkeypatch.undo()
    packed, g_packed = results[0]
    assert len(g_packed) == len(list(net.parameters()))
    for out, grads in results:
        assert out[~mask].abs().max() == 0
        torch.testing.assert_close(out[mask], packed[mask], atol=1e-5, rtol=1e-5)
        assert grads.keys() == g_packed.keys()
        for name in grads:
            torch.testing.assert_close(grads[name], g_packed[name], atol=1e-5, rtol=1e-4)


def test_cpu_training_path_equals_sdpa_without_dropout():
    """Training on CPU spells attention out (for the cheap dropout); with dropout 0 it must
    give the SDPA path's numbers, gradients included."""
    torch.manual_seed(0)
    net = GoalConditionedDT(DTConfig(state_dim=24, action_dim=3, context=6, dropout=0.0))
    inputs = _inputs()
    inputs["mask"][0, :2] = False
    outs, grads = [], []
    for train in (True, False):
        net.train(train)
        net.zero_grad()
        out = net(**inputs)
        out.sum().backward()
        outs.append(out.detach())
        grads.append(net.blocks[0].qkv.weight.grad.clone())
    torch.testing.assert_close(outs[0], outs[1], atol=1e-5, rtol=1e-5)
    torch.testing.assert_close(grads[0], grads[1], atol=1e-5, rtol=1e-4)


def test_dropout_drops_p_keeps_the_mean_and_follows_torch_seed():
    x = torch.ones(200, 1000)
    torch.manual_seed(3)
    y = dropout(x, 0.1, training=True)
    assert abs((y == 0).float().mean().item() - 0.1) < 0.003
    assert abs(y.mean().item() - 1.0) < 0.01
    values = torch.unique(y).tolist()
    assert values[0] == 0.0 and values[1:] == [pytest.approx(65536 / (65536 - 6554))]
    torch.manual_seed(3)
    assert torch.equal(dropout(x, 0.1, training=True), y)  # reproducible from torch's seed
    assert not torch.equal(dropout(x, 0.1, training=True), y)  # a fresh mask per call
    assert dropout(x, 0.1, training=False) is x
    g = torch.ones(5, requires_grad=True)
    torch.manual_seed(0)
    out = dropout(g, 0.5, training=True)
    out.sum().backward()
    torch.testing.assert_close(g.grad, out.detach())  # gradient flows through the kept units


def test_in_place_residual_dropout_computes_the_same_numbers_and_gradients():
    x0, y0 = torch.randn(4, 30, 16), torch.randn(4, 30, 16)
    results = []
    for fused in (False, True):
        x, y = x0.clone().requires_grad_(), y0.clone().requires_grad_()
        torch.manual_seed(7)
        out = add_dropout(x, y * 1.0, 0.1, True) if fused else x + dropout(y * 1.0, 0.1, True)
        (out * torch.arange(16.0)).sum().backward()
        results.append((out.detach(), x.grad, y.grad))
    for plain, fused in zip(*results, strict=True):
        assert torch.equal(plain, fused)  # bit for bit: results do not depend on the fast path
    assert torch.equal(add_dropout(x0, y0.clone(), 0.1, training=False), x0 + y0)


@pytest.mark.parametrize("shape", [(1,), (3,), (5, 7), (64, 60, 128)])
def test_cpu_dropout_mask_is_the_documented_stream(shape):
    """The mask's bits are `Generator.bytes` of SFC64 seeded from torch's generator, as
    first written: reading the raw words instead must not change any run's numbers."""
    x = torch.ones(shape)
    torch.manual_seed(11)
    seed = int(torch.randint(0, 2**62, (1,)))
    n = x.numel()
    bits = np.frombuffer(np.random.Generator(np.random.SFC64(seed)).bytes(2 * n), np.uint16)
    expected = (bits.reshape(shape) >= 6554).astype(np.float32) * np.float32(65536 / 58982)
    torch.manual_seed(11)
    assert torch.equal(_cpu_keep_scale(x, 0.1), torch.from_numpy(expected))
