"""gcdt: Goal-Conditioned Decision Transformer for multi-goal offline RL on panda-gym.

The library follows one data flow: env -> policy -> collector -> dataset -> trainer ->
checkpoint -> evaluator -> results -> report. This release holds the first and the last
of the online pieces: the tasks (`gcdt.envs`), the policies (`gcdt.policies`) and the
evaluator (`gcdt.evaluation`).
"""

from gcdt.errors import GcdtError

__version__ = "0.1.0"
__all__ = ["GcdtError", "__version__"]
