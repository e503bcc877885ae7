"""Reading back the files advgame writes, with one clear error when one is damaged.

Every reader of a run, results or population file goes through `reading` (or `read_json` /
`read_csv`, built on it): a file that is missing is a `ConfigError` (the user named a wrong
path); a file that exists but does not parse is a `FileFormatError` that names the file, says
whether it looks empty, truncated, not of its format or written by another version, and how to
recover.

Example:
    >>> import tempfile, pathlib
    >>> bad = pathlib.Path(tempfile.mkdtemp()) / "state.json"
    >>> _ = bad.write_text('{"iteration": 3, "rng"')
    >>> try:
    ...     read_json(bad, "run state", fix="rerun `advgame train`")
    ... except FileFormatError as exc:
    ...     print(str(bad) in str(exc), "truncated" in str(exc))
    True True

"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import pickle
import zipfile
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

from advgame.errors import AdvgameError, ConfigError, FileFormatError

__all__ = ["diagnose", "read_csv", "read_json", "reading", "require"]

_TRUNCATED = (EOFError,)
_OTHER_VERSION = (KeyError, TypeError, AttributeError, ModuleNotFoundError, IndexError)


def diagnose(path: str | Path, exc: BaseException | None = None) -> str:
    """What looks wrong with `path`, in words, given the exception its reader raised."""
    path = Path(path)
    try:
        size = path.stat().st_size
        head = path.open("rb").read(4)
    except OSError as err:
        return f"cannot be opened ({err.strerror or err})"
    if size == 0:
        return "is empty (0 bytes)"
    zipped = isinstance(exc, zipfile.BadZipFile) or "zip" in str(exc).lower()
    if path.suffix in (".zip", ".npz") or zipped:
        if head != b"PK\x03\x04":
            return f"is not a zip archive (it starts with {head!r})"
        if not _whole_zip(path):
            return f"looks truncated ({size} bytes; its zip directory or members are cut short)"
    if isinstance(exc, json.JSONDecodeError):
        text = exc.doc.rstrip()
        if exc.msg.startswith("Unterminated") or not text.endswith(("}", "]")):
            return f"looks truncated (its JSON stops after {size} bytes: {exc.msg})"
        return f"is not valid JSON ({exc})"
    if isinstance(exc, _TRUNCATED) or "truncated" in str(exc):
        return f"looks truncated ({size} bytes; {type(exc).__name__}: {exc})"
    if isinstance(exc, pickle.UnpicklingError):
        return f"is not a pickle advgame or SB3 wrote ({exc})"
    if isinstance(exc, _OTHER_VERSION):
        return (
            "does not have the layout this version of advgame writes; it may be truncated or "
            f"written by another version ({type(exc).__name__}: {exc})"
        )
    return f"cannot be parsed ({type(exc).__name__}: {exc})"


def _whole_zip(path: Path) -> bool:
    """Whether `path` is one whole zip archive, every member's CRC right.

    A cut SB3 checkpoint may still show a zip directory: that of a torch archive stored inside
    it, whose members do not start at byte 0.
    """
    try:
        with zipfile.ZipFile(path) as zf:
            infos = zf.infolist()
            starts_at_0 = bool(infos) and min(i.header_offset for i in infos) == 0
            return starts_at_0 and zf.testzip() is None
    except Exception:  # a damaged archive may fail in many ways; any of them means "not whole"
        return False


def _missing(path: Path, what: str, fix: str) -> ConfigError:
    where = "folder" if path.parent.is_dir() else "folder, which does not exist either"
    return ConfigError(f"No {what} at {path} (checked its {where}). {fix}")


@contextlib.contextmanager
def reading(path: str | Path, what: str, fix: str) -> Iterator[Path]:
    """Turn any failure while parsing `path` into a `FileFormatError` naming it.

    `what` names the file kind ("run state", "population file"); `fix` says how to recover.
    A missing file is a `ConfigError`; an `AdvgameError` raised inside passes unchanged.
    """
    path = Path(path)
    if not path.exists():
        raise _missing(path, what, fix)
    try:
        yield path
    except AdvgameError:
        raise
    except Exception as exc:
        raise FileFormatError(
            f"The {what} {path} {diagnose(path, exc)}. {fix}", path=str(path)
        ) from exc


def read_json(path: str | Path, what: str, fix: str, kind: type = object) -> Any:
    """Parse the JSON file `path`; its top level must be of type `kind` (e.g. ``dict``)."""
    with reading(path, what, fix) as p:
        data = json.loads(p.read_text())
    if not isinstance(data, kind):
        raise FileFormatError(
            f"The {what} {path} holds a JSON {type(data).__name__}, not a {kind.__name__}: it "
            f"was not written by this version of advgame. {fix}",
            path=str(path),
        )
    return data


def read_csv(path: str | Path, what: str, fix: str, columns: Sequence[str]) -> list[dict[str, str]]:
    """The rows of CSV file `path`: every row has every cell, and a value in each of `columns`."""
    with reading(path, what, fix) as p:
        text = p.read_text()
        rows = list(csv.DictReader(io.StringIO(text, newline="")))
    if not text.endswith("\n"):  # every writer ends its header and rows with a newline
        problem = "looks truncated: its last row is cut short" if text else "is empty (0 bytes)"
        raise FileFormatError(f"The {what} {path} {problem}. {fix}", path=str(path))
    missing = [c for c in columns if not rows or c not in rows[0]]
    if missing and rows:
        raise FileFormatError(
            f"The {what} {path} lacks the column(s) {missing}: it was written by another "
            f"version of advgame or another program. {fix}",
            path=str(path),
        )
    for i, row in enumerate(rows, start=2):
        cut = None in row or any(v is None for v in row.values())  # too many or too few cells
        if cut or any(row.get(c) == "" for c in columns):
            raise FileFormatError(
                f"The {what} {path} has a short or broken row on line {i}; it looks truncated. "
                f"{fix}",
                path=str(path),
            )
    return rows


def require(data: Any, keys: Sequence[str], path: str | Path, what: str, fix: str) -> None:
    """Check that the parsed mapping `data` of `path` has every one of `keys`."""
    missing = [k for k in keys if not isinstance(data, dict) or k not in data]
    if missing:
        raise FileFormatError(
            f"The {what} {path} lacks {missing}: it looks truncated or written by another "
            f"version of advgame. {fix}",
            path=str(path),
        )
