"""gcdt: Goal-Conditioned Decision Transformer for multi-goal offline RL on panda-gym.

One data flow, env -> policy -> dataset -> trainer -> checkpoint -> evaluator -> results ->
report, one module or package per step:

- `gcdt.envs` (the tasks), `gcdt.regions` (goal regions), `gcdt.policies`, `gcdt.rollout`
  (the one stepping loop);
- `gcdt.data`: offline datasets (collection, subsets and mixtures, Minari, the authors' files);
- `gcdt.models` (GC-DT and BC; `gcdt.fast_forward`, `gcdt.hf_reference`), `gcdt.methods`
  (the methods by name), `gcdt.training` and its checkpoints (`gcdt.checkpoint`);
- `gcdt.evaluation`: the one evaluator; `gcdt.explorer`: a rollout towards a chosen goal;
- `gcdt.baselines`: TQC+HER, the online baseline and expert;
- `gcdt.experiments`: the grid of the paper's runs, their store and sweeps;
- `gcdt.report`: tables, figures, the README's results and the reproduction check;
- `gcdt.cli`: the `gcdt` command; `gcdt.papermill_engine`: the notebooks' engine;
- `gcdt.paths`, `gcdt.provenance`, `gcdt.settings`, `gcdt.device`, `gcdt.progress`,
  `gcdt.errors`: what they all share.
"""

from gcdt.errors import GcdtError

__version__ = "0.1.0"
__all__ = ["GcdtError", "__version__"]
