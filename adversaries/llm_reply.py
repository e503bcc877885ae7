"""Replies from a language model are untrusted input: parse, check, project, count.

`parse_reply` turns a reply string into a vector of exactly `size` finite numbers inside a box
``[low, high]``, or rejects it with a named status. Nothing is evaluated: the text goes through
`json.loads` only (with NaN, Infinity and overflowing literals refused), so prose, nested
objects, wrong lengths, huge or non-finite numbers and text that tries to change the
instructions are all just rejected data.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["REJECTIONS", "Reply", "parse_reply", "reply_schema"]

REJECTIONS = (
    "empty",
    "too_long",
    "not_json",
    "no_values",
    "not_numbers",
    "wrong_length",
    "non_finite",
)
"""Every reason a reply can be rejected (the policy then plays its fallback)."""

_ARRAY = re.compile(r"\[[^\[\]{}]*\]")
_NUMBER = (int, float)


@dataclass(frozen=True)
class Reply:
    """A parsed reply: the projected values, or why there are none."""

    status: str
    """``"ok"``, ``"clipped"`` (valid but projected into the box) or one of `REJECTIONS`."""
    values: np.ndarray | None = None
    """The values after projection into ``[low, high]`` (``None`` when rejected)."""
    clipped: int = 0
    """How many components the projection moved."""

    @property
    def accepted(self) -> bool:
        """Whether the reply gave a usable vector."""
        return self.values is not None


def _reject_constant(name: str) -> float:
    raise ValueError(f"non-finite literal {name}")


def _finite_float(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):  # "1e309" parses to inf
        raise ValueError(f"non-finite number {text[:20]}")
    return value


def _loads(text: str) -> Any:
    return json.loads(text, parse_constant=_reject_constant, parse_float=_finite_float)


def _candidate(text: str) -> Any:
    """The JSON value in `text`: the whole text, else the first flat ``[...]`` in it."""
    try:
        return _loads(text)
    except (ValueError, RecursionError):
        pass
    match = _ARRAY.search(text)  # plain-prompt fallback: a model that chats around its answer
    if match is None:
        raise ValueError("no JSON value")
    return _loads(match.group(0))


def _numbers(value: Any) -> list | None:
    """The list of values: a bare list, or the ``"values"`` list of an object."""
    if isinstance(value, dict):
        value = value.get("values")
    return value if isinstance(value, list) else None


def parse_reply(
    text: Any, size: int, low: np.ndarray, high: np.ndarray, max_chars: int = 4000
) -> Reply:
    """Parse `text` into `size` finite numbers projected into ``[low, high]``.

    Accepted forms: ``{"values": [..]}`` or ``[..]``, either alone or (plain-prompt fallback)
    the first flat ``[..]`` inside other text. Booleans, strings, nested lists or objects,
    NaN, infinities and numbers that overflow a float are rejected, never coerced.

    Example:
        >>> import numpy as np
        >>> parse_reply('{"values": [0.5, 9]}', 2, np.zeros(2), np.ones(2))
        Reply(status='clipped', values=array([0.5, 1. ]), clipped=1)
        >>> parse_reply('{"values": [NaN, 0]}', 2, np.zeros(2), np.ones(2)).status
        'not_json'

    """
    if not isinstance(text, str) or not text.strip():
        return Reply("empty")
    if len(text) > max_chars:
        return Reply("too_long")
    try:
        value = _candidate(text.strip())
    except (ValueError, RecursionError):
        return Reply("not_json")
    items = _numbers(value)
    if items is None:
        return Reply("no_values")
    if not all(type(x) in _NUMBER for x in items):  # bool is not int here: type(), not isinstance
        return Reply("not_numbers")
    if len(items) != size:
        return Reply("wrong_length")
    try:
        arr = np.array(items, dtype=np.float64)
    except OverflowError:  # an integer literal beyond float range
        return Reply("non_finite")
    if not np.all(np.isfinite(arr)):
        return Reply("non_finite")
    out = np.clip(arr, low, high)
    clipped = int(np.count_nonzero(out != arr))
    return Reply("clipped" if clipped else "ok", out, clipped)


def reply_schema(size: int) -> dict:
    """The JSON schema of a reply: ``{"values": [size numbers]}``, nothing else."""
    return {
        "type": "object",
        "properties": {
            "values": {
                "type": "array",
                "items": {"type": "number"},
                "minItems": size,
                "maxItems": size,
            }
        },
        "required": ["values"],
        "additionalProperties": False,
    }
