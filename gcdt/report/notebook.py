"""The notebooks' helpers: their parameters checked, where they read and write, a figure
saved and shown, a grid run (or, over the published results, not)."""

from __future__ import annotations

from pathlib import Path

from gcdt.errors import GcdtError
from gcdt.experiments.profiles import PROFILES, Profile
from gcdt.paths import OUTPUTS_ENV, REPO_ROOT, artifacts_dir, is_published, results_dir
from gcdt.report import figures


def check_parameters(profile: object, backend: object) -> Profile:
    """Validate notebook parameters (papermill may inject anything); return the profile."""
    from gcdt.experiments.sweep import BACKENDS

    if not isinstance(profile, str) or profile not in PROFILES:
        raise GcdtError(
            f"parameter profile must be one of {', '.join(PROFILES)} (a string), got {profile!r}"
        )
    if not isinstance(backend, str) or backend not in BACKENDS:
        raise GcdtError(
            f"parameter backend must be one of {', '.join(BACKENDS)} (a string), got {backend!r}"
        )
    return PROFILES[profile]


def renders_published(profile: Profile) -> bool:
    """Whether a notebook reads the repository's published results of `profile` (JupyterLab
    without `$GCDT_OUTPUTS`): it then renders them and never runs or rewrites anything there;
    `make reproduce` is what re-runs. The smoke profile publishes nothing, so it always runs."""
    return is_published() and profile.name != "smoke"


def outputs_note(profile: Profile) -> str:
    """Which results a notebook reads and writes: the published ones, or a reproduction's."""
    where = results_dir(profile.name)
    shown = where.relative_to(REPO_ROOT) if where.is_relative_to(REPO_ROOT) else where
    if renders_published(profile):
        return (
            f"Results: {shown}/ (the repository's published results, rendered as they are; "
            f"figures drawn here go to {notebook_figures_dir(profile)})"
        )
    if is_published():
        return f"Results: {shown}/ (this checkout's own {profile.name} runs)"
    return f"Results: {shown}/ (this reproduction's own folder, ${OUTPUTS_ENV})"


def notebook_figures_dir(profile: Profile) -> Path:
    """Where a notebook saves what it draws: the results' figures folder, except over the
    published results, whose figures only `make publish` and `make figures` write."""
    if renders_published(profile):
        return artifacts_dir() / "notebooks" / profile.name
    return figures.figures_dir(profile.name)


def show(fig, profile: Profile, name: str) -> None:
    """Save `fig` as `name` (PNG, PDF) in `notebook_figures_dir` and display it once; a
    figure that does not exist (None: no run of its section) is said so instead."""
    from IPython.display import display

    if fig is None:
        print(f"{name}: profile {profile.name} has no runs for this figure")
        return
    figures.save(fig, notebook_figures_dir(profile), name)
    display(fig)


def run_grid(profile: Profile, backend: str, methods: tuple[str, ...] | None = None) -> None:
    """A notebook's sweep: run what is not done yet, or nothing over the published results."""
    from gcdt.experiments.sweep import sweep

    if renders_published(profile):
        print(
            f"rendering the published {profile.name} results: `make reproduce "
            f"PROFILE={profile.name}` re-runs them into a folder of your own"
        )
        return
    summary = sweep(profile, backend=backend, methods=methods, progress=False)
    print("\n".join(summary.lines()))
    if not summary.ok:
        raise GcdtError(
            f"{summary.line()}: see the failed result files in {results_dir(profile.name)}/runs"
        )
