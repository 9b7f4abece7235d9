"""Where generated bulk (datasets, checkpoints, logs, executed notebooks) lives."""

from __future__ import annotations

import os
from pathlib import Path

#: Environment variable that relocates the artifacts folder (e.g. to a scratch disk).
ARTIFACTS_ENV = "GCDT_ARTIFACTS"

REPO_ROOT = Path(__file__).resolve().parent.parent


def artifacts_dir() -> Path:
    """The git-ignored artifacts folder: `$GCDT_ARTIFACTS`, else `<repo>/artifacts`."""
    return Path(os.environ.get(ARTIFACTS_ENV) or REPO_ROOT / "artifacts")
