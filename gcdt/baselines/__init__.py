"""Baselines of Table 1 besides the offline learners of `gcdt.training` (DT and BC)."""
