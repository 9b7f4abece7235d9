"""Goal regions: a box of the goal space that a task's desired goals are drawn from.

panda-gym draws each episode's desired goal uniformly from its task's `goal_range_low` /
`goal_range_high` box, shifted up by half the object's size on Push and PickAndPlace (the
cube's centre rests at that height on the table). A `GoalRegion` is a box in world
coordinates (metres); `restrict_goals` narrows the task's box to its intersection with the
region, through those public attributes, so that the env itself draws its goals from the
region with its own seeded random generator. Used to train on goals of one region and to
evaluate inside and outside it (goal generalisation).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from gcdt.errors import GcdtError

AXES = ("x", "y", "z")


@dataclass(frozen=True)
class GoalRegion:
    """An axis-aligned box of desired goals, world coordinates; unbounded axes are infinite."""

    low: tuple[float, float, float] = (-math.inf, -math.inf, -math.inf)
    high: tuple[float, float, float] = (math.inf, math.inf, math.inf)

    def __post_init__(self) -> None:
        for axis, lo, hi in zip(AXES, self.low, self.high, strict=True):
            if math.isnan(lo) or math.isnan(hi) or lo > hi:
                raise GcdtError(
                    f"goal region {axis} bounds must be numbers with low <= high, got {lo}:{hi}"
                )

    @classmethod
    def parse(cls, text: str) -> GoalRegion:
        """`"x=0:0.15,y=-0.1:0.1"`: bounds per axis, LOW:HIGH (either may be empty: open)."""
        low, high = [-math.inf] * 3, [math.inf] * 3
        for part in filter(None, (p.strip() for p in text.split(","))):
            axis, _, bounds = part.partition("=")
            lo, sep, hi = bounds.partition(":")
            if axis not in AXES or not sep:
                raise GcdtError(
                    f"bad goal region {text!r}: expected AXIS=LOW:HIGH parts for axes "
                    f"{', '.join(AXES)}, e.g. x=0:0.15,y=-0.1:0.1"
                )
            i = AXES.index(axis)
            try:
                low[i] = float(lo) if lo.strip() else -math.inf
                high[i] = float(hi) if hi.strip() else math.inf
            except ValueError:
                raise GcdtError(
                    f"bad goal region {text!r}: bounds of {axis} must be numbers"
                ) from None
        return cls(tuple(low), tuple(high))

    def __str__(self) -> str:
        parts = [
            f"{axis}={'' if math.isinf(lo) else f'{lo:g}'}:{'' if math.isinf(hi) else f'{hi:g}'}"
            for axis, lo, hi in zip(AXES, self.low, self.high, strict=True)
            if not (math.isinf(lo) and math.isinf(hi))
        ]
        return ",".join(parts) or "everywhere"

    def describe(self) -> str:
        """For readers: "y=:0" reads "y ≤ 0", "y=0:" "y ≥ 0", "x=0:0.15" "0 ≤ x ≤ 0.15"."""
        parts = []
        for axis, lo, hi in zip(AXES, self.low, self.high, strict=True):
            if math.isinf(lo) and math.isinf(hi):
                continue
            if math.isinf(lo):
                parts.append(f"{axis} ≤ {hi:g}")
            elif math.isinf(hi):
                parts.append(f"{axis} ≥ {lo:g}")
            else:
                parts.append(f"{lo:g} ≤ {axis} ≤ {hi:g}")
        return ", ".join(parts) or "everywhere"

    def contains(self, goals: np.ndarray) -> np.ndarray:
        """Which of `goals` ([n, 3], world coordinates) lie in the region."""
        goals = np.asarray(goals, dtype=np.float64)
        return np.all((goals >= self.low) & (goals <= self.high), axis=-1)


def _offset(task: Any) -> np.ndarray:
    """panda-gym's shift of the goal box: the cube's centre height on object tasks."""
    size = getattr(task, "object_size", None)
    return np.array([0.0, 0.0, 0.0 if size is None else size / 2])


def goal_box(task: Any) -> tuple[np.ndarray, np.ndarray]:
    """The world-coordinate box that `task` (a panda-gym task) draws its goals from; a task
    whose desired goal is more than one position (Stack: two cubes) is refused."""
    size = task.get_goal().size
    if size != len(AXES):
        raise GcdtError(
            f"{type(task).__name__}'s desired goal is {size // len(AXES)} positions: a goal of "
            "your choice works on tasks with one (Reach, Push, PickAndPlace, Slide)"
        )
    offset = _offset(task)
    return task.goal_range_low + offset, task.goal_range_high + offset


def _box_text(low: np.ndarray, high: np.ndarray) -> str:
    return ", ".join(f"{a} [{lo:.3f}, {hi:.3f}]" for a, lo, hi in zip(AXES, low, high, strict=True))


def check_goal(task: Any, goal: np.ndarray) -> None:
    """Refuse a desired goal that `task` (a panda-gym task) could never draw itself."""
    goal = np.asarray(goal, dtype=np.float64)
    low, high = goal_box(task)
    if goal.shape != low.shape or not np.all(np.isfinite(goal)):
        raise GcdtError(f"a goal is {low.size} finite coordinates x, y, z, got {goal.tolist()}")
    if np.any(goal < low - 1e-6) or np.any(goal > high + 1e-6):  # float32 slider round-off
        where = ", ".join(f"{v:.3f}" for v in goal)
        raise GcdtError(
            f"goal ({where}) lies outside {type(task).__name__}'s goal range: "
            f"{_box_text(low, high)}"
        )


def restrict_goals(task: Any, region: GoalRegion) -> None:
    """Make `task` draw its goals from its box intersected with `region` (in place)."""
    low, high = goal_box(task)
    new_low, new_high = np.maximum(low, region.low), np.minimum(high, region.high)
    if np.any(new_low > new_high):
        raise GcdtError(
            f"goal region {region} contains no goal of this task: its goals lie in "
            f"{_box_text(low, high)}"
        )
    # PickAndPlace puts 30 % of its goals on the table whatever its box says: a region above
    # the table would not hold them.
    if type(task).__name__ == "PickAndPlace" and new_low[2] > low[2]:
        raise GcdtError(
            f"goal region {region} lies above the table, but PickAndPlace draws 30 % of its "
            f"goals on the table (z = {low[2]:.3f}): give z a lower bound of at most that"
        )
    offset = _offset(task)
    task.goal_range_low, task.goal_range_high = new_low - offset, new_high - offset
