"""gcdt: Goal-Conditioned Decision Transformer for multi-goal offline RL on panda-gym.

The library follows one data flow: env -> policy -> collector -> dataset -> trainer ->
checkpoint -> evaluator -> results -> report. Built so far: the tasks (`gcdt.envs`), the
policies (`gcdt.policies`), the stepping loop they run in (`gcdt.rollout`), the evaluator
(`gcdt.evaluation`), the offline datasets (`gcdt.data`), the models (`gcdt.models`),
their trainer (`gcdt.training`) and its checkpoints (`gcdt.checkpoint`).
"""

from gcdt.errors import GcdtError

__version__ = "0.1.0"
__all__ = ["GcdtError", "__version__"]
