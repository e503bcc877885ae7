"""Config dataclasses as files and command lines: field docs, JSON round trips, CLI overrides.

Configs are frozen dataclasses with a docstring under each field (read here with `ast`, so the
docstring is the single source of the ``--help`` text). Values are JSON-friendly scalars,
strings, lists and dicts. `write_atomic` is how run and results files are written.
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
import inspect
import itertools
import json
import os
import textwrap
import typing
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any, TypeVar

from advgame.errors import ConfigError, did_you_mean

__all__ = [
    "add_arguments",
    "field_docs",
    "from_dict",
    "load_json",
    "override",
    "save_json",
    "scalar_field",
    "to_dict",
    "write_atomic",
]

T = TypeVar("T")


def field_docs(cls: type) -> dict[str, str]:
    """The docstring written under each field of dataclass `cls` (and its bases)."""
    docs: dict[str, str] = {}
    for klass in reversed(cls.__mro__):
        if not dataclasses.is_dataclass(klass):
            continue
        try:
            tree = ast.parse(textwrap.dedent(inspect.getsource(klass)))
        except (OSError, TypeError):
            continue
        body = tree.body[0].body if tree.body and isinstance(tree.body[0], ast.ClassDef) else []
        for node, nxt in itertools.pairwise(body):
            if (
                isinstance(node, ast.AnnAssign)
                and isinstance(node.target, ast.Name)
                and isinstance(nxt, ast.Expr)
                and isinstance(nxt.value, ast.Constant)
                and isinstance(nxt.value.value, str)
            ):
                docs[node.target.id] = " ".join(nxt.value.value.split())
    return docs


def to_dict(cfg: Any) -> dict[str, Any]:
    """A config as a plain dict (nested dataclasses included)."""
    return dataclasses.asdict(cfg)


def from_dict(cls: type[T], data: dict[str, Any]) -> T:
    """Build config `cls` from a dict, naming unknown keys with a suggestion.

    Raises:
        ConfigError: `data` is not a mapping, names an unknown option or lacks a required one.

    """
    fields = dataclasses.fields(cls)  # type: ignore[arg-type]
    names = {f.name for f in fields}
    if not isinstance(data, Mapping):
        raise ConfigError(
            f"{cls.__name__} options must be a mapping {{option: value}}, got {data!r}. "
            f"Options: {sorted(names)}."
        )
    required = [f.name for f in fields if f.init and _required(f) and f.name not in data]
    if required:
        raise ConfigError(
            f"{cls.__name__} needs the option(s) {required}, got only {sorted(data)}."
        )
    for key in data:
        if key not in names:
            raise ConfigError(
                f"Unknown {cls.__name__} option {key!r}.{did_you_mean(key, names)} "
                f"Options: {sorted(names)}."
            )
    hints = typing.get_type_hints(cls)
    values = {k: _coerce(hints[k], v) for k, v in data.items()}
    return cls(**values)


def _required(f: dataclasses.Field[Any]) -> bool:
    return f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING


def _coerce(hint: Any, value: Any) -> Any:
    origin = typing.get_origin(hint)
    if origin is tuple and isinstance(value, list):
        return tuple(value)
    if origin in (typing.Union, getattr(__import__("types"), "UnionType", None)):
        args = [a for a in typing.get_args(hint) if a is not type(None)]
        if value is not None and len(args) == 1:
            return _coerce(args[0], value)
    return value


def write_atomic(path: str | Path, data: str | bytes) -> None:
    """Write `data` to `path` through a temporary file beside it and one rename.

    A kill at any moment leaves the old file or the new one, never part of one; the temporary
    name carries the process id, so processes writing the same path do not collide.
    """
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    if isinstance(data, bytes):
        tmp.write_bytes(data)
    else:
        tmp.write_text(data)
    os.replace(tmp, path)


def read_json(path: str | Path, what: str, keys: Iterable[str] = ()) -> Any:
    """Read a JSON file advgame wrote, with the keys its top level must have.

    A missing file is a `ConfigError`; an empty, truncated or garbled one, or one without
    `keys` (another version, or edited), a `FileFormatError` saying which
    (`advgame.core.files.read_json`).
    """
    from advgame.core.files import read_json as _read
    from advgame.core.files import require

    fix = f"restore {Path(path).name} or rerun the step that wrote it"
    keys = list(keys)
    data = _read(path, what, fix, kind=dict if keys else object)
    if keys:
        require(data, keys, path, what, fix)
    return data


def save_json(cfg: Any, path: str | Path) -> None:
    """Write a config as JSON."""
    Path(path).write_text(json.dumps(to_dict(cfg), indent=2, sort_keys=True) + "\n")


def load_json(cls: type[T], path: str | Path) -> T:
    """Read a config from JSON written by `save_json` (or by hand).

    Raises:
        ConfigError: no file at `path`, or a value in it is invalid.
        FileFormatError: the file is empty, truncated or not a JSON object.

    """
    from advgame.core.files import read_json

    fix = (
        f"Fix or delete {path}; `advgame train --help` lists every {cls.__name__} field, and "
        "a run writes its config.json when it starts."
    )
    return from_dict(cls, read_json(path, f"{cls.__name__} file", fix, kind=dict))


def override(cfg: T, assignments: list[str]) -> T:
    """Apply ``key=value`` overrides (values parsed as JSON when they parse, else strings)."""
    data = to_dict(cfg)
    for item in assignments:
        key, sep, raw = item.partition("=")
        if not sep:
            raise ConfigError(f"Override {item!r} is not key=value (e.g. iterations=5).")
        try:
            data[key.strip()] = json.loads(raw)
        except json.JSONDecodeError:
            data[key.strip()] = raw
    return from_dict(type(cfg), data)


def add_arguments(parser: argparse.ArgumentParser, cls: type) -> None:
    """One ``--field-name`` option per scalar field of `cls`, with its docstring as help."""
    docs = field_docs(cls)
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        hint = hints[f.name]
        kind = _scalar(hint)
        if kind is None:
            continue
        default = f.default if f.default is not dataclasses.MISSING else None
        flag = "--" + f.name.replace("_", "-")
        help_text = f"{docs.get(f.name, '')} (default: {default})"
        if kind is bool:
            parser.add_argument(
                flag,
                dest=f.name,
                action=argparse.BooleanOptionalAction,
                default=None,
                help=help_text,
            )
        else:
            parser.add_argument(
                flag,
                dest=f.name,
                type=kind,
                default=None,
                help=help_text,
                choices=typing.get_args(hint)
                if typing.get_origin(hint) is typing.Literal
                else None,
            )


def scalar_field(cls: type, name: str) -> bool:
    """Whether field `name` of `cls` gets its own command-line flag (a scalar or a Literal)."""
    return _scalar(typing.get_type_hints(cls)[name]) is not None


def _scalar(hint: Any) -> type | None:
    if hint in (int, float, str, bool):
        return hint
    if typing.get_origin(hint) is typing.Literal:
        return type(typing.get_args(hint)[0])
    args = [a for a in typing.get_args(hint) if a is not type(None)]
    if len(args) == 1 and args[0] in (int, float, str):
        return args[0]
    return None
