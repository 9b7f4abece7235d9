"""Where generated bulk (datasets, checkpoints, logs, executed notebooks) lives."""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path
from typing import Any

#: Environment variable that relocates the artifacts folder (e.g. to a scratch disk).
ARTIFACTS_ENV = "GCDT_ARTIFACTS"

REPO_ROOT = Path(__file__).resolve().parent.parent


def artifacts_dir() -> Path:
    """The git-ignored artifacts folder: `$GCDT_ARTIFACTS`, else `<repo>/artifacts`."""
    return Path(os.environ.get(ARTIFACTS_ENV) or REPO_ROOT / "artifacts")


def write_json_atomic(path: str | Path, data: Any) -> Path:
    """Write `data` as JSON to `path` via a temp file and a rename: never half a file."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w") as f:
            json.dump(data, f, indent=2)
            f.write("\n")
        os.replace(tmp, path)
    except BaseException:
        os.unlink(tmp)
        raise
    return path
