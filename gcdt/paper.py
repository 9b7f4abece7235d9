"""The paper's protocol, each constant defined once with where it comes from.

The experiments (Table 1, Section V's Fig. 3 and Fig. 4) and the authors' public code, which
fixes what the paper leaves unsaid (the training recipe, the evaluation budget). Configs,
profiles and defaults read these; a reduced profile states each departure from them
(`gcdt.experiments.profiles.deviations`). TQC+HER's hyperparameters are the paper's too, and
live in `gcdt/baselines/tqc_her.yaml`; the DT's shape is `gcdt.models.DTConfig`'s defaults.
Measured numbers are not constants: they live in results/ and the docs generated from them.
"""

from __future__ import annotations

#: Training seeds per grid cell: the paper's "3 random seeds" (Table 1, Fig. 3 and Fig. 4).
SEEDS = (0, 1, 2)
#: Transitions of each task's expert dataset (Table 1; Fig. 3's and Fig. 4's full data).
DATASET_SIZE = 1_000_000
#: Dataset sizes of RQ4 (Section V, Fig. 3): subsets of the expert data.
RQ4_SIZES = (100_000, 250_000, 500_000, 750_000, 1_000_000)
#: Expert shares of RQ5 (Section V, Fig. 4): expert/random mixtures at the full size.
RQ5_RATIOS = (0.0, 0.25, 0.5, 0.75, 1.0)

# Offline training (GC-DT, the DT ablations, BC): the authors' public code.
#: Training budget: epochs of ceil(#episodes / batch size) gradient steps.
EPOCHS = 120
BATCH_SIZE = 64
#: AdamW's peak learning rate and weight decay.
LEARNING_RATE = 1e-4
WEIGHT_DECAY = 1e-4
#: Share of the steps of linear warm-up (then linear decay).
WARMUP_FRACTION = 0.1
GRAD_CLIP = 0.25
#: Returns-to-go are divided by this.
RETURN_SCALE = 100.0

# Evaluation: the authors' public code.
#: Env steps per evaluation, counting every episode that finishes within them.
EVAL_TIMESTEPS = 10_000
#: A DT's target return at each episode's start.
TARGET_RETURN = 0.0
