"""Goal regions: envs that draw their desired goals from a box, and the bad regions refused."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gcdt.envs import episode_seed, make_env, make_vec_env
from gcdt.errors import GcdtError
from gcdt.evaluation import evaluate
from gcdt.policies import ScriptedExpert
from gcdt.regions import GoalRegion

LEFT = GoalRegion.parse("y=:0")


def _goals(task: str, region: GoalRegion | None, n: int = 40) -> np.ndarray:
    env = make_env(task, "sparse", goal_region=region)
    try:
        return np.array([env.reset(seed=episode_seed(7, j))[0]["desired_goal"] for j in range(n)])
    finally:
        env.close()


@pytest.mark.parametrize("task", ["reach", "push", "pick_and_place"])
def test_an_env_draws_its_goals_from_the_region(task):
    anywhere, left = _goals(task, None), _goals(task, LEFT)
    assert not LEFT.contains(anywhere).all()  # without the region, goals fall on both halves
    assert LEFT.contains(left).all()
    # Only the restricted axis changed: the others keep the task's range (and its seeding).
    assert np.ptp(left[:, 0]) > 0.1 and left[:, 1].min() < -0.05


def test_parallel_envs_take_the_region_too():
    region = GoalRegion.parse("x=0:0.1,y=0:")
    envs = make_vec_env("push", "sparse", 2, goal_region=region)
    try:
        obs, _ = envs.reset(seed=[episode_seed(1, 0), episode_seed(1, 1)])
    finally:
        envs.close()
    assert region.contains(obs["desired_goal"]).all()


def test_evaluation_in_a_region_records_it():
    expert = ScriptedExpert("reach")
    result = evaluate(expert, "reach", "sparse", episodes=5, goal_region=LEFT, progress=False)
    assert result.summary["goal_region"] == "y=:0" and result.summary["success_rate"] == 1.0
    assert "goal_region" not in evaluate(expert, "reach", "sparse", episodes=1).summary


def test_region_text_round_trips():
    region = GoalRegion.parse("x=-0.1:0.1, z=0.05:")
    assert region.low == (-0.1, -math.inf, 0.05) and region.high == (0.1, math.inf, math.inf)
    assert str(region) == "x=-0.1:0.1,z=0.05:" and GoalRegion.parse(str(region)) == region
    assert str(GoalRegion()) == "everywhere"
    # For readers (tables, figures): bounds as inequalities.
    assert region.describe() == "-0.1 ≤ x ≤ 0.1, z ≥ 0.05" and LEFT.describe() == "y ≤ 0"
    assert GoalRegion().describe() == "everywhere"


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("w=0:1", "expected AXIS=LOW:HIGH parts for axes x, y, z"),
        ("x=0", "expected AXIS=LOW:HIGH parts"),
        ("x=a:1", "bounds of x must be numbers"),
        ("y=0.2:0.1", "y bounds must be numbers with low <= high"),
        ("y=nan:0", "y bounds must be numbers with low <= high"),
    ],
)
def test_bad_region_text_is_refused(text, message):
    with pytest.raises(GcdtError, match=message):
        GoalRegion.parse(text)


def test_regions_without_goals_are_refused():
    with pytest.raises(GcdtError, match=r"contains no goal of this task: its goals lie in x \["):
        make_env("push", "sparse", goal_region=GoalRegion.parse("y=0.5:"))
    with pytest.raises(GcdtError, match="PickAndPlace draws 30 % of its goals on the table"):
        make_env("pick_and_place", "sparse", goal_region=GoalRegion.parse("z=0.1:"))


def test_cli_refuses_a_bad_region_and_writes_nothing(assert_usage_error, tmp_path):
    out = tmp_path / "eval.json"
    base = ["evaluate", "--policy", "scripted", "--task", "push", "--reward", "sparse"]
    assert_usage_error(
        [*base, "--goal-region", "y=0.5:", "--out", str(out)],
        "contains no goal of this task",
    )
    assert_usage_error([*base, "--goal-region", "y=1"], "expected AXIS=LOW:HIGH parts")
    assert not out.exists()


def test_a_collection_in_a_region_holds_only_its_goals(tmp_path):
    from gcdt.cli import main
    from gcdt.data import load_dataset

    out = tmp_path / "left.npz"
    argv = ["collect", "--policy", "scripted", "--task", "push", "--transitions", "200"]
    assert main([*argv, "--goal-region", "y=:0", "--out", str(out), "--no-progress"]) == 0
    data = load_dataset(out)
    assert LEFT.contains(data.arrays["desired_goal"]).all()
    assert data.metadata["goal_region"] == "y=:0" and data.summary()["success_rate"] > 0.9
