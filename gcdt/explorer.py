"""The interactive explorer: a trained GC-DT, a goal and a target return of your choice.

`explore` is the whole logic: one recorded rollout of a checkpoint towards a chosen goal, with
the final step's attention; every bad choice is refused with one line (`GcdtError`).
`Explorer` lays it out as ipywidgets for JupyterLab (notebook 07): a task, a checkpoint, x/y/z
sliders within the task's goal range, a target return and an episode seed; each change rolls
out again and shows the animation, the success, the return and the attention map.
"""

from __future__ import annotations

import io
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from html import escape
from pathlib import Path
from typing import Any

import numpy as np

from gcdt import paper
from gcdt.envs import TASKS, get_task, goal_range
from gcdt.errors import GcdtError
from gcdt.evaluation import Recording, record_rollout
from gcdt.regions import AXES

#: A checkpoint: its file, or a function that returns it (a grid checkpoint, trained on first
#: use; `gcdt.experiments.artifacts.checkpoint`).
CheckpointSource = str | Path | Callable[[], Path]
#: Where the goal sliders start, as a fraction of each axis of the task's goal range.
START = (0.75, 0.25, 0.5)


@dataclass(frozen=True)
class Exploration:
    """One rollout of the explorer."""

    task: str
    checkpoint: str
    target_return: float
    recording: Recording
    attention: np.ndarray | None  # [layers, heads, 3K, 3K] at the last step; None for BC

    def summary(self) -> str:
        rec = self.recording
        goal = ", ".join(f"{v:.3f}" for v in rec.goal)
        return (
            f"{rec.verdict}, return {rec.ret:.2f} over {rec.steps} step{'s' * (rec.steps != 1)} "
            f"(goal ({goal}), target return {self.target_return:g})"
        )

    def figure(self):
        """Distance to the goal per step and the attention map (`rollout_figure`)."""
        from gcdt.report.figures import rollout_figure

        return rollout_figure(
            self.recording, get_task(self.task).distance_threshold, self.attention
        )


def parse_target(text: str | float) -> float:
    """A target return from a widget's text: a finite number, or a one-line error."""
    try:
        value = float(text)
    except (TypeError, ValueError):
        value = math.nan
    if not math.isfinite(value):
        raise GcdtError(
            f"target return must be a finite number (0 is the paper's; a sparse episode "
            f"returns between -50 and 0), got {str(text)!r}"
        )
    return value


def explore(
    checkpoint: str | Path,
    task: str,
    goal: np.ndarray,
    target_return: float = paper.TARGET_RETURN,
    *,
    seed: int = 0,
    size: int = 200,
) -> Exploration:
    """Roll `checkpoint` out once on `task` towards `goal` (world coordinates, within the
    task's goal range) from the start of evaluation episode 0 of `seed`."""
    from gcdt.policies.trained import TrainedPolicy

    # Refuses a checkpoint of another task and a target that is not a finite number.
    policy = TrainedPolicy(checkpoint, get_task(task).name, target_return=target_return)
    reward = policy.config()["reward"] or "sparse"  # BC runs under either reward
    recording = record_rollout(policy, task, reward, seed, size=size, goal=goal)
    attention = policy.attention() if policy.method == "dt" else None
    return Exploration(task, str(checkpoint), float(target_return), recording, attention)


def png(fig) -> bytes:
    """A matplotlib figure as PNG bytes (closed afterwards: widgets show it, not pyplot)."""
    import matplotlib.pyplot as plt

    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=80, bbox_inches="tight")
    plt.close(fig)
    return buffer.getvalue()


class Explorer:
    """The widgets. `checkpoints` maps each task to its labelled checkpoints; the checkpoint
    box also takes a file path. `Explorer(...).widget` is what a notebook displays."""

    def __init__(
        self,
        checkpoints: Mapping[str, Mapping[str, CheckpointSource]],
        *,
        seed: int = 0,
        size: int = 200,
    ) -> None:
        import ipywidgets as w

        if not checkpoints or not all(checkpoints.values()):
            raise GcdtError("the explorer needs at least one checkpoint for each task it offers")
        self.checkpoints = {get_task(t).name: dict(c) for t, c in checkpoints.items()}
        self.size, self.rollouts, self.last = size, 0, None
        self._quiet = False  # set while the widgets are updated together: one rollout after
        wide = {"description_width": "110px"}
        tasks = list(self.checkpoints)
        self.task = w.Dropdown(options=tasks, value=tasks[0], description="task", style=wide)
        self.checkpoint = w.Combobox(
            description="checkpoint",
            placeholder="a checkpoint above, or a checkpoint.pt path",
            ensure_option=False,
            continuous_update=False,  # a typed path rolls out once, on Enter or leaving the box
            style=wide,
            layout=w.Layout(width="560px"),
        )
        self.sliders = [
            w.FloatSlider(
                description=f"goal {axis} (m)",
                step=0.005,
                readout_format=".3f",
                continuous_update=False,
                style=wide,
                layout=w.Layout(width="560px"),
            )
            for axis in AXES
        ]
        self.target = w.Text(
            value="0", description="target return", continuous_update=False, style=wide
        )
        self.seed = w.BoundedIntText(
            value=seed, min=0, max=2**31 - 1, description="episode seed", style=wide
        )
        self.button = w.Button(description="Roll out", icon="play")
        self.status = w.HTML()
        self.animation = w.Image(format="gif", layout=w.Layout(width=f"{size}px"))
        self.figure = w.Image(format="png")
        self.animation.add_class("gcdt-animation")
        self.figure.add_class("gcdt-figure")
        self.status.add_class("gcdt-status")
        self.task.observe(lambda _: self._task_changed(), "value")
        for control in (self.checkpoint, *self.sliders, self.target, self.seed):
            control.observe(lambda _: self.run(), "value")
        self.button.on_click(lambda _: self.run())
        self.widget = w.VBox(
            [
                w.HBox([self.task, self.seed]),
                self.checkpoint,
                *self.sliders,
                w.HBox([self.target, self.button]),
                self.status,
                w.HBox([self.animation, self.figure]),
            ]
        )
        self._task_changed()

    def _task_changed(self) -> None:
        """Another task: its checkpoints and its goal range (sliders at `START`), then a rollout."""
        task = self.task.value
        low, high = goal_range(task)
        self._quiet = True
        try:
            labels = list(self.checkpoints[task])
            self.checkpoint.options = labels
            self.checkpoint.value = labels[0]
            # Off the middle, where Reach's gripper starts: a goal it has to travel to.
            for slider, lo, hi, start in zip(self.sliders, low, high, START, strict=True):
                # Widen before narrowing: a slider refuses min > max on the way.
                slider.min, slider.max = min(slider.min, lo), max(slider.max, hi)
                slider.min, slider.max = float(lo), float(hi)
                slider.value = float(lo + start * (hi - lo))
                slider.disabled = bool(hi - lo < 1e-9)  # Push: goals lie on the table
        finally:
            self._quiet = False
        self.run()

    def _checkpoint_path(self) -> Path:
        choice = self.checkpoint.value.strip()
        source = self.checkpoints[self.task.value].get(choice, choice)
        if callable(source):
            self._say(f"preparing checkpoint {escape(choice)} (trained once, then reused) ...")
            return source()
        if not choice:
            raise GcdtError("choose a checkpoint, or give a checkpoint.pt path")
        return Path(source)

    def run(self) -> Exploration | None:
        """Roll out with the widgets' values; a bad value is shown as one line instead."""
        if self._quiet:
            return None
        try:
            target = parse_target(self.target.value)
            goal = np.array([s.value for s in self.sliders], dtype=np.float64)
            path = self._checkpoint_path()
            self._say("rolling out ...")
            result = explore(
                path, self.task.value, goal, target, seed=int(self.seed.value), size=self.size
            )
        except GcdtError as err:
            self._say(f"✗ {escape(str(err))}", error=True)
            return None
        except Exception as err:  # shown, not lost in the kernel's log; the last rollout stays
            self._say(f"✗ {type(err).__name__}: {escape(str(err))}", error=True)
            return None
        self.rollouts += 1
        self.last = result
        self.animation.value = result.recording.gif()
        self.figure.value = png(result.figure())
        self._say(f"rollout {self.rollouts}: {escape(result.summary())}")
        return result

    def _say(self, text: str, *, error: bool = False) -> None:
        colour = "#b00020" if error else "inherit"
        kind = "gcdt-error" if error else "gcdt-message"
        self.status.value = f'<span class="{kind}" style="color:{colour}">{text}</span>'


def grid_checkpoints(profile: Any) -> dict[str, dict[str, Callable[[], Path]]]:
    """The Table 1 GC-DT checkpoints of a profile, by task: label -> trained on first use."""
    from gcdt.experiments import artifacts, build_grid

    specs = [e.spec for e in build_grid(profile, only="table1") if e.spec.method == "gcdt"]
    out: dict[str, dict[str, Callable[[], Path]]] = {t: {} for t in TASKS}
    for spec in sorted(specs, key=lambda s: (s.reward != "sparse", s.seed)):  # sparse first
        label = f"GC-DT, {spec.reward} reward, seed {spec.seed} ({profile.name} grid)"
        out[spec.task][label] = lambda spec=spec: artifacts.checkpoint(spec)
    return {task: labels for task, labels in out.items() if labels}


__all__ = ["Exploration", "Explorer", "explore", "grid_checkpoints", "parse_target", "png"]
