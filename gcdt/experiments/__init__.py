"""The experiment grid of the paper: profiles, runs, the run store, and sweeps over them.

get_profile(name) -> Profile              # smoke|quick|standard|paper (gcdt.experiments.profiles)
build_grid(profile, only=None)            # every RunSpec, each once (gcdt.experiments.grid)
sweep(profile, backend="local"|"ray")     # run what is not done yet (gcdt.experiments.sweep)
"""

from gcdt.experiments.grid import SECTIONS, GridEntry, RunSpec, build_grid
from gcdt.experiments.profiles import PROFILES, Profile, deviations, deviations_text, get_profile
from gcdt.experiments.store import RunStore
from gcdt.experiments.sweep import BACKENDS, SweepSummary, plan, sweep
from gcdt.paths import results_dir

__all__ = [
    "BACKENDS",
    "PROFILES",
    "SECTIONS",
    "GridEntry",
    "Profile",
    "RunSpec",
    "RunStore",
    "SweepSummary",
    "build_grid",
    "deviations",
    "deviations_text",
    "get_profile",
    "plan",
    "results_dir",
    "sweep",
]
