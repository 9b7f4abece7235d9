"""gcdt.explorer without a browser: a chosen goal reached, the widgets' rollouts, bad input."""

from __future__ import annotations

import numpy as np
import pytest

from gcdt.data import collect
from gcdt.errors import GcdtError
from gcdt.explorer import Explorer, explore, parse_target
from gcdt.policies.scripted import ScriptedExpert
from gcdt.training import TrainConfig, train


@pytest.fixture(scope="module")
def checkpoints(reach_gcdt, tmp_path_factory):
    """The shared Reach GC-DT that reaches goals, and a Push one that need not."""
    data = collect(ScriptedExpert("push"), "push", 300, seed=0, progress=False)
    cfg = TrainConfig(method="dt", steps=2, context=5)
    push = train(data, cfg, tmp_path_factory.mktemp("push"), progress=False).checkpoint
    return {"reach": reach_gcdt.checkpoint, "push": push}


@pytest.mark.parametrize("goal", [(0.1, -0.1, 0.25), (-0.12, 0.1, 0.05)])
def test_a_trained_gcdt_reaches_a_goal_of_our_choice(checkpoints, goal):
    result = explore(checkpoints["reach"], "reach", np.array(goal), seed=3, size=48)
    rec = result.recording
    np.testing.assert_allclose(rec.goal, goal, atol=1e-6)
    assert rec.success and rec.distances[-1] < 0.05 < rec.distances[0], rec.distances
    assert rec.ret == -(rec.steps - 1)  # sparse: -1 per step until the successful last one
    assert result.attention is not None and result.attention.shape[-1] == 15  # 3 tokens x K=5
    assert result.summary().startswith("success, return")


def test_the_widgets_roll_out_on_every_change(checkpoints):
    explorer = Explorer({"reach": {"tiny": checkpoints["reach"]}}, size=48)
    assert explorer.rollouts == 1  # the first rollout, at the start of the sliders
    assert [s.value for s in explorer.sliders] == pytest.approx([0.075, -0.075, 0.15])
    bounds = [bound for s in explorer.sliders for bound in (s.min, s.max)]
    assert bounds == pytest.approx([-0.15, 0.15, -0.15, 0.15, 0.0, 0.3])
    explorer.sliders[0].value = 0.1
    assert explorer.rollouts == 2 and "rollout 2: success" in explorer.status.value
    assert explorer.last.recording.goal[0] == pytest.approx(0.1)
    assert explorer.animation.value[:6] == b"GIF89a" and explorer.figure.value[:4] == b"\x89PNG"
    explorer.target.value = "-4"
    assert explorer.rollouts == 3 and explorer.last.target_return == -4.0


def test_the_widgets_say_what_is_wrong_and_keep_the_last_rollout(checkpoints):
    explorer = Explorer(
        {"reach": {"tiny": checkpoints["reach"]}, "push": {"tiny push": checkpoints["push"]}},
        size=48,
    )
    first, shown = explorer.last, explorer.figure.value
    explorer.target.value = "nan"
    assert "target return must be a finite number" in explorer.status.value
    assert "gcdt-error" in explorer.status.value and explorer.rollouts == 1
    assert explorer.last is first and explorer.figure.value is shown  # the last one stays
    explorer.target.value = "-1"
    second, shown = explorer.last, explorer.figure.value
    assert explorer.rollouts == 2 and second is not first
    explorer.checkpoint.value = str(checkpoints["push"])  # a path typed into the box
    assert (
        f"checkpoint {checkpoints['push']} is for task &#x27;push&#x27;, not &#x27;reach&#x27;"
        in explorer.status.value
    )
    assert explorer.last is second and explorer.figure.value is shown  # nothing new drawn
    explorer.task.value = "push"  # Push's goals lie on the table: z is fixed
    assert explorer.sliders[2].disabled and explorer.sliders[2].value == pytest.approx(0.02)
    assert explorer.rollouts == 3 and explorer.checkpoint.value == "tiny push"


def test_bad_choices_are_refused_in_one_line(checkpoints):
    with pytest.raises(GcdtError, match=r"goal \(0.000, 0.000, 0.400\) lies outside Reach's"):
        explore(checkpoints["reach"], "reach", np.array([0.0, 0.0, 0.4]))
    with pytest.raises(GcdtError, match="is for task 'push', not 'reach': choose a reach"):
        explore(checkpoints["push"], "reach", np.array([0.0, 0.0, 0.1]))
    with pytest.raises(GcdtError, match=r"target return must be a finite number .* got 'inf'"):
        parse_target("inf")
    with pytest.raises(GcdtError, match=r"got 'minus two'"):
        parse_target("minus two")
    with pytest.raises(GcdtError, match="at least one checkpoint"):
        Explorer({"reach": {}})
    with pytest.raises(GcdtError, match="Stack's desired goal is 2 positions"):
        Explorer({"stack": {"any": checkpoints["push"]}})
    assert parse_target(" -6.5 ") == -6.5


def test_the_rollout_command_records_a_chosen_goal(checkpoints, tmp_path, capsys):
    from gcdt.cli import main

    out = tmp_path / "reach.gif"
    ckpt = str(checkpoints["reach"])
    argv = ["rollout", "--policy", ckpt, "--task", "reach", "--reward", "sparse"]
    assert main([*argv, "--goal", "0.1,-0.1,0.25", "--size", "32", "--out", str(out)]) == 0
    assert "towards (0.100, -0.100, 0.250): success, return" in capsys.readouterr().out
    assert out.read_bytes()[:6] == b"GIF89a"


def test_the_rollout_command_refuses_bad_choices(checkpoints, tmp_path, assert_usage_error):
    out = tmp_path / "never.gif"
    base = ["rollout", "--task", "reach", "--reward", "sparse", "--out", str(out)]
    reach, push = str(checkpoints["reach"]), str(checkpoints["push"])
    assert_usage_error(
        [*base, "--policy", reach, "--goal", "0,0,0.5"],
        "goal (0.000, 0.000, 0.500) lies outside Reach's goal range: x [-0.150, 0.150]",
    )
    assert_usage_error(
        [*base, "--policy", reach, "--goal", "0,0"], "a goal is three numbers X,Y,Z in metres"
    )
    assert_usage_error(
        [*base, "--policy", reach, "--target-return", "nan"],
        "target return must be a finite number",
    )
    assert_usage_error([*base, "--policy", push], "is for task 'push', not 'reach'")
    png = ["rollout", "--task", "reach", "--reward", "sparse", "--policy", reach]
    assert_usage_error([*png, "--out", str(tmp_path / "a.png")], "GIF files ending in .gif")
    stack = ["rollout", "--task", "stack", "--reward", "sparse", "--policy", "random"]
    assert_usage_error(
        [*stack, "--goal", "0,0,0.1", "--out", str(out)], "Stack's desired goal is 2 positions"
    )
    assert not out.exists() and not list(tmp_path.iterdir())
