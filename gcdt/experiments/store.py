"""The run store: one JSON result per run under `results/<profile>/runs/<key>.json`.

Results are written atomically (temp file + rename), so a killed sweep leaves either a whole
result or none. A run counts as done only if its file parses, names the same key and schema,
and says `"status": "done"`; anything else (failed, corrupt, foreign) is reported and re-run.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from gcdt.experiments.grid import RUN_SCHEMA
from gcdt.paths import write_json_atomic

#: What a result file says about its run.
STATES = ("done", "failed", "missing", "corrupt")


@dataclass(frozen=True)
class StoredRun:
    state: str  # one of STATES
    result: dict[str, Any] | None
    problem: str | None = None  # why a file is not trusted (corrupt state)


class RunStore:
    """Result files of one profile, keyed by `RunSpec.key()`."""

    def __init__(self, root: str | Path) -> None:
        self.root = Path(root)

    def path(self, key: str) -> Path:
        return self.root / f"{key}.json"

    def read(self, key: str) -> StoredRun:
        path = self.path(key)
        if not path.exists():
            return StoredRun("missing", None)
        try:
            result = json.loads(path.read_text())
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
            return StoredRun("corrupt", None, f"{path.name} is not valid JSON ({err})")
        if not isinstance(result, dict) or result.get("key") != key:
            return StoredRun("corrupt", None, f"{path.name} is not the result of run {key}")
        if result.get("schema") != RUN_SCHEMA:
            return StoredRun(
                "corrupt",
                None,
                f"{path.name} has result schema {result.get('schema')!r}, not {RUN_SCHEMA}",
            )
        state = result.get("status")
        if state not in ("done", "failed"):
            return StoredRun("corrupt", None, f"{path.name} has unknown status {state!r}")
        return StoredRun(state, result)

    def write(self, key: str, result: dict[str, Any]) -> Path:
        return write_json_atomic(self.path(key), result)

    def foreign_files(self, keys: set[str]) -> list[Path]:
        """JSON files in the store that belong to no run of the grid (reported, never used)."""
        if not self.root.exists():
            return []
        return sorted(p for p in self.root.glob("*.json") if p.stem not in keys)

    def remove_partial_files(self) -> None:
        """Delete temp files a killed writer left behind (never a result: they are renamed
        into place only once complete)."""
        if self.root.exists():
            for path in self.root.glob(".*.tmp"):
                path.unlink(missing_ok=True)
