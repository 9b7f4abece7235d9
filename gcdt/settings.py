"""Settings declared once: a dataclass field with its default, its help text and, for an
integer, the least value it may take. `TrainConfig`, `EvaluationConfig` and every command of
`gcdt` (`gcdt.cli`) are made of them; `add_options` turns such a dataclass into the command's
options and `from_options` builds it back from what was parsed, so a flag is one field.

Validation lives in the dataclass's `__post_init__` (`check_minimums` for the minimums), for
library callers and the command line alike: argparse only converts text to the field's type.
"""

from __future__ import annotations

import argparse
import dataclasses
import typing
from collections.abc import Callable, Iterable, Mapping
from dataclasses import MISSING, field, fields
from pathlib import Path
from typing import Any

from gcdt.errors import GcdtError

#: The default of a setting that must be given (a required option).
REQUIRED: Any = MISSING


def setting(
    default: Any,
    help: str,
    *,
    minimum: int | None = None,
    flag: str | None = None,
    metavar: str | None = None,
    choices: Iterable[str] | Callable[[], Iterable[str]] | None = None,
    parse: Callable[[str], Any] | None = None,
    positional: bool = False,
) -> Any:
    """A config field: its default (`REQUIRED`: none), what it means (`--help` shows it), and
    for an integer the least value it may take. For the command line: its `flag` (default
    `--field-name`), `metavar`, `choices` (a `Literal` type gives them too; a function: read
    when the command parses), `parse` (text -> value, raising `GcdtError`), `positional`."""
    given = {
        "minimum": minimum,
        "flag": flag,
        "metavar": metavar,
        "choices": choices,
        "parse": parse,
        "positional": positional or None,
    }
    metadata = {"help": help, **{k: v for k, v in given.items() if v is not None}}
    return field(default=default, metadata=metadata)


def check_minimums(config: Any, integer: type | tuple[type, ...] = int) -> None:
    """Refuse a field of the dataclass `config` that has a `minimum` and holds anything but an
    `integer` of at least that value (None passes: "not given")."""
    for f in fields(config):
        minimum, value = f.metadata.get("minimum"), getattr(config, f.name)
        if minimum is None or value is None:
            continue
        if isinstance(value, bool) or not isinstance(value, integer) or value < minimum:
            wanted = {1: "a positive integer", 0: "a non-negative integer"}.get(
                minimum, f"an integer >= {minimum}"
            )
            raise GcdtError(f"{f.name} must be {wanted}, got {value!r}")


def add_options(
    parser: argparse.ArgumentParser, config: type, names: Mapping | None = None
) -> None:
    """An option per field of the dataclass `config`, from its type and `setting` metadata; a
    field not made by `setting` is a dataclass that adds its fields' options. `names` resolves
    annotations that `config`'s module imports only when a command runs (a torch module's)."""
    kinds = typing.get_type_hints(config, localns=dict(names or {}))
    for f in fields(config):
        kind, meta = _optional(kinds[f.name]), f.metadata
        if _nested(f):
            add_options(parser, kind, names)
            continue
        option: dict[str, Any] = {"help": meta["help"]}
        if kind is bool:
            option["action"] = "store_true"
        else:
            choices = meta.get("choices")
            if typing.get_origin(kind) is typing.Literal:
                choices = typing.get_args(kind)
            option["choices"] = list(choices() if callable(choices) else choices or ()) or None
            option["type"] = _converter(meta.get("parse") or (str if choices else kind))
            option["metavar"] = meta.get("metavar")
            if f.default not in (None, MISSING):
                option["help"] += " (default: %(default)s)"
        if f.default is not MISSING:
            option["default"] = f.default
        if meta.get("positional"):
            parser.add_argument(f.name, **option)
        else:
            flag = meta.get("flag") or f"--{f.name.replace('_', '-')}"
            parser.add_argument(flag, dest=f.name, required=f.default is MISSING, **option)


def from_options(values: Mapping[str, Any], config: type, names: Mapping | None = None) -> Any:
    """The dataclass `config` (validated by its `__post_init__`) from the parsed `values` of
    its options (`add_options`)."""
    kinds = typing.get_type_hints(config, localns=dict(names or {}))
    return config(
        **{
            f.name: from_options(values, kinds[f.name], names) if _nested(f) else values[f.name]
            for f in fields(config)
        }
    )


def _nested(f: dataclasses.Field) -> bool:
    """Whether `f` is a dataclass whose fields are options: a field not made by `setting`."""
    return "help" not in f.metadata


def _optional(kind: Any) -> Any:
    """`X` for `X | None`, else `kind`."""
    args = [a for a in typing.get_args(kind) if a is not type(None)]
    return args[0] if type(None) in typing.get_args(kind) and len(args) == 1 else kind


def _converter(convert: Callable[[str], Any]) -> Callable[[str], Any]:
    """`convert` as an argparse type: a `GcdtError` becomes argparse's one-line error."""
    if convert in (str, int, float, Path):
        return convert

    def parse(text: str) -> Any:
        try:
            return convert(text)
        except GcdtError as err:
            raise argparse.ArgumentTypeError(str(err)) from None

    return parse
