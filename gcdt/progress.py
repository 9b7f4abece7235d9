"""The library's one progress-bar factory (collection, training, evaluation, sweeps, TQC+HER)."""

from __future__ import annotations

from typing import Any

from tqdm.auto import tqdm


def progress_bar(*, progress: bool, **kwargs: Any) -> tqdm:
    """A tqdm bar, drawn only when `progress` is set and its output (stderr) is a terminal.

    `disable=None` is tqdm's "disable unless the output is a TTY": logs, pipes and CI get no
    bar, and neither does a Jupyter kernel, whose stderr is no TTY either. `progress=False`
    (the CLI's `--no-progress`) always hides it. Other keyword arguments go to tqdm as they are.
    """
    return tqdm(disable=None if progress else True, **kwargs)
