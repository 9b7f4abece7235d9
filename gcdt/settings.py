"""Settings declared once: a dataclass field with its default, its help text (which the
command line shows) and, for an integer, the least value it may take. `TrainConfig` and
`EvaluationConfig` are made of them, and `gcdt train` / `gcdt evaluate` take each as an option."""

from __future__ import annotations

from dataclasses import field, fields
from typing import Any

from gcdt.errors import GcdtError


def setting(default: Any, help: str, *, minimum: int | None = None) -> Any:
    """A config field: its default, what it means (`--help` shows it), and for an integer the
    least value it may take."""
    metadata = {"help": help} if minimum is None else {"help": help, "minimum": minimum}
    return field(default=default, metadata=metadata)


def check_minimums(config: Any, integer: type | tuple[type, ...] = int) -> None:
    """Refuse a field of the dataclass `config` that has a `minimum` and holds anything but an
    `integer` of at least that value (None passes: "not given")."""
    for f in fields(config):
        minimum, value = f.metadata.get("minimum"), getattr(config, f.name)
        if minimum is None or value is None:
            continue
        if not isinstance(value, integer) or value < minimum:
            wanted = {1: "a positive integer", 0: "a non-negative integer"}.get(
                minimum, f"an integer >= {minimum}"
            )
            raise GcdtError(f"{f.name} must be {wanted}, got {value!r}")
