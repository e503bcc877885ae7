"""Type checks of config dataclass fields against their annotations, with one clear message.

Configs come from JSON files, dicts and command lines as much as from code, so a field may
hold anything. `check_fields` compares each value with its annotation (numbers, bools,
strings, `Literal` choices, ``None`` unions, sequences, mappings and nested dataclasses) and
raises a `ConfigError` naming the field, the value, what was expected and the field's own
documentation. Value ranges stay in each class's ``__post_init__``.

Example:
    >>> from advgame.core.schedule import Schedule
    >>> try:
    ...     Schedule(every="often")
    ... except ConfigError as exc:
    ...     print(str(exc).split(".")[0] + ".every ...")
    Schedule.every ...

"""

from __future__ import annotations

import collections.abc as abc
import dataclasses
import functools
import numbers
import types
import typing
from typing import Any

import numpy as np

from advgame.errors import ConfigError

__all__ = ["check_fields", "describe", "matches"]


@functools.cache
def _hints(cls: type) -> dict[str, Any]:
    names = {f.name for f in dataclasses.fields(cls)}
    return {k: v for k, v in typing.get_type_hints(cls).items() if k in names}


def check_fields(obj: Any, skip: tuple[str, ...] = ()) -> None:
    """Raise `ConfigError` if a field of dataclass `obj`, but those in `skip`, mistypes."""
    cls: Any = type(obj)
    for name, hint in _hints(cls).items():
        if name in skip:
            continue
        value = getattr(obj, name)
        if not matches(hint, value):
            raise ConfigError(
                f"{cls.__name__}.{name} must be {describe(hint)}, got {value!r} "
                f"({type(value).__name__}).{_doc(cls, name)}"
            )


def _doc(cls: type, name: str) -> str:
    from advgame.core.config import field_docs

    doc = field_docs(cls).get(name, "")
    return f" It is: {doc}" if doc else ""


def _number(value: Any) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


def _scalar(hint: Any, value: Any) -> bool | None:
    """Whether `value` matches a scalar `hint`; None when `hint` is not a scalar type."""
    if hint is bool:
        return isinstance(value, (bool, np.bool_))
    if hint is int:
        return isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_))
    if hint is float:  # NaN and inf are numbers: each class's own range check names them
        return _number(value)
    if hint is str:
        return isinstance(value, str)
    return None


def _sequence(args: tuple[Any, ...], value: Any, fixed: bool) -> bool:
    if isinstance(value, (str, bytes)) or not isinstance(value, (list, tuple, np.ndarray)):
        return False
    items = list(value)
    if fixed:
        return len(items) == len(args) and all(
            matches(a, v) for a, v in zip(args, items, strict=True)
        )
    item = args[0] if args else Any
    return all(matches(item, v) for v in items)


def matches(hint: Any, value: Any) -> bool:
    """Whether `value` fits the type annotation `hint` (unknown annotations always fit)."""
    if hint is Any or hint is object:
        return True
    if hint is type(None) or hint is None:
        return value is None
    scalar = _scalar(hint, value)
    if scalar is not None:
        return scalar
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin in (typing.Union, types.UnionType):
        return any(matches(a, value) for a in args)
    if origin is typing.Literal:
        return any(type(value) is type(a) and value == a for a in args)
    if origin is tuple:
        fixed = not (len(args) == 2 and args[1] is Ellipsis)
        return _sequence(args if fixed else args[:1], value, fixed)
    if origin in (list, abc.Sequence):
        return _sequence(args, value, fixed=False)
    if origin in (dict, abc.Mapping):
        key, item = args if args else (Any, Any)
        return isinstance(value, abc.Mapping) and all(
            matches(key, k) and matches(item, v) for k, v in value.items()
        )
    if isinstance(hint, type):
        return isinstance(value, hint)
    return True


_PLURAL = {bool: "booleans", int: "integers", float: "numbers", str: "strings"}


def describe(hint: Any) -> str:
    """An annotation in words: ``float | Sequence[float]`` is "a finite number or a list of ..."."""
    if hint is type(None) or hint is None:
        return "None"
    words = {bool: "true or false", int: "an integer", float: "a number", str: "a string"}
    if hint in words:
        return words[hint]
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin in (typing.Union, types.UnionType):
        return " or ".join(describe(a) for a in args)
    if origin is typing.Literal:
        return "one of " + ", ".join(repr(a) for a in args)
    if origin in (tuple, list, abc.Sequence):
        if origin is tuple and not (len(args) == 2 and args[1] is Ellipsis):
            return f"a list of {len(args)}: " + ", ".join(describe(a) for a in args)
        item = args[0] if args else Any
        return f"a list of {_PLURAL[item]}" if item in _PLURAL else f"a list of ({describe(item)})"
    if origin in (dict, abc.Mapping):
        return f"a mapping from ({describe(args[0])}) to ({describe(args[1])})"
    if isinstance(hint, type) and dataclasses.is_dataclass(hint):
        return f"a {hint.__name__} (or a dict of its fields)"
    return f"a {getattr(hint, '__name__', hint)}"
