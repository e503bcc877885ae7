"""An off-policy learner's replay buffer as append-only files of its filled rows.

Stable-Baselines3 pickles a replay buffer whole, preallocated arrays and all: 200 MB for
Hopper's 1M transitions however few are filled, and a new file at every checkpoint. To carry a
run in training from one checkout to another through git (`advgame.workflows.park`), the buffer
is stored instead as

* **chunks**: ``NNNNNNNNN-MMMMMMMMM-DIGEST.npz`` files of rows ``[N, M)`` of every per-row array
  (compressed; ``next_observations`` keeps only the rows that differ from the next row's
  ``observations``, the last of an episode), written once and never changed while the buffer
  has not wrapped, so storing the buffer again later adds only the rows that came since;
* **a manifest** (JSON) naming the chunks, the arrays' shapes and dtypes, and the buffer
  object itself, pickled with those arrays emptied (its position, its other state: OMPO's
  first states, for one).

`store_buffer` writes the chunks a buffer needs beyond those already in the folder and
returns the manifest; `load_buffer` rebuilds the buffer, bit for bit, from a manifest and its
chunks. A buffer that wrapped (or whose stored rows changed) is written again in full.
"""

from __future__ import annotations

import base64
import copy
import hashlib
import pickle
from pathlib import Path
from typing import Any

import numpy as np

from advgame.errors import FileFormatError

__all__ = ["FORMAT", "filled", "load_buffer", "row_arrays", "store_buffer"]

FORMAT = 1
"""Version of the manifest layout."""


def row_arrays(buffer: Any) -> dict[str, np.ndarray]:
    """The buffer's per-row arrays by name (``observations``, ``observations.KEY`` for dicts).

    A per-row array is an attribute whose first dimension is the buffer's size: what SB3's
    replay buffers (plain, Dict, HER) keep their transitions in.
    """
    rows = int(buffer.buffer_size)
    found: dict[str, np.ndarray] = {}
    for name, value in vars(buffer).items():
        if isinstance(value, np.ndarray) and value.ndim and value.shape[0] == rows:
            found[name] = value
        elif isinstance(value, dict):
            for key, item in value.items():
                if isinstance(item, np.ndarray) and item.ndim and item.shape[0] == rows:
                    found[f"{name}.{key}"] = item
    return found


def _put(buffer: Any, name: str, array: np.ndarray) -> None:
    """Set the per-row array `name` of `buffer` (``row_arrays``' naming, dict members too)."""
    attr, _, key = name.partition(".")
    if key and isinstance(getattr(buffer, attr, None), dict):
        getattr(buffer, attr)[key] = array
    else:
        setattr(buffer, name, array)


def filled(buffer: Any) -> int:
    """How many rows of an SB3 replay buffer hold transitions (per env): all once it wrapped."""
    return int(buffer.buffer_size) if buffer.full else int(buffer.pos)


def _digest(arrays: dict[str, np.ndarray], start: int, end: int) -> str:
    h = hashlib.blake2b(digest_size=16)
    for name in sorted(arrays):
        h.update(name.encode())
        h.update(np.ascontiguousarray(arrays[name][start:end]).tobytes())
    return h.hexdigest()


def _write_chunk(
    arrays: dict[str, np.ndarray], start: int, end: int, folder: Path, digest: str
) -> str:
    """Rows ``[start, end)`` of every array into one compressed file; returns its name.

    The name carries the rows' digest, so other rows under the same range (a wrapped buffer)
    never overwrite a chunk an earlier manifest still reads.
    """
    out: dict[str, np.ndarray] = {}
    for name, array in arrays.items():
        out[name] = array[start:end]
    nxt, obs = arrays.get("next_observations"), arrays.get("observations")
    if nxt is not None and obs is not None and nxt.shape == obs.shape:
        # next_observations[i] is observations[i + 1] but at an episode's end: keep the others
        same = np.zeros(nxt[start:end].shape[:2], dtype=bool)
        inner = nxt[start : end - 1] == obs[start + 1 : end]
        same[:-1] = inner.reshape(*inner.shape[:2], -1).all(axis=-1)
        del out["next_observations"]
        out["next_observations.differs"] = ~same
        out["next_observations.values"] = nxt[start:end][~same]
    name = f"{start:09d}-{end:09d}-{digest[:12]}.npz"
    tmp = folder / f"{name}.tmp"
    with tmp.open("wb") as f:
        np.savez_compressed(f, **out)
    tmp.replace(folder / name)
    return name


def _read_chunk(path: Path, names: list[str]) -> dict[str, np.ndarray]:
    with np.load(path) as data:
        rows = {k: data[k] for k in data.files}
    if "next_observations.differs" in rows:
        differs = rows.pop("next_observations.differs")
        values = rows.pop("next_observations.values")
        obs = rows["observations"]
        nxt = np.empty_like(obs)
        nxt[:-1] = obs[1:]
        nxt[differs] = values
        rows["next_observations"] = nxt
    missing = sorted(set(names) - set(rows))
    if missing:
        raise FileFormatError(f"{path} lacks the replay rows of {missing}.", path=str(path))
    return rows


def store_buffer(buffer: Any, folder: Path, previous: dict[str, Any] | None = None) -> dict:
    """Write the chunks `buffer` needs into `folder`; return its manifest (JSON-able).

    `previous` is the manifest of an earlier `store_buffer` of the same buffer into the same
    folder: its chunks are reused where the buffer still holds the same rows, so only the rows
    added since are written. Chunk files no manifest names any more are the caller's to delete.
    """
    folder.mkdir(parents=True, exist_ok=True)
    arrays = row_arrays(buffer)
    used = filled(buffer)
    chunks: list[dict[str, Any]] = []
    if previous and not buffer.full:
        for chunk in previous.get("chunks", []):
            start, end = int(chunk["start"]), int(chunk["end"])
            intact = (folder / chunk["file"]).is_file() and end <= used
            if not intact or _digest(arrays, start, end) != chunk["digest"]:
                chunks = []  # rows changed under a stored chunk: store everything again
                break
            chunks.append(chunk)
    start = chunks[-1]["end"] if chunks else 0
    if used > start:
        digest = _digest(arrays, start, used)
        name = _write_chunk(arrays, start, used, folder, digest)
        chunks.append({"start": start, "end": used, "file": name, "digest": digest})
    skeleton = copy.copy(buffer)
    for attr, value in vars(buffer).items():  # its own dicts, so emptying leaves `buffer` whole
        if isinstance(value, dict):
            setattr(skeleton, attr, dict(value))
    for name, array in arrays.items():
        _put(skeleton, name, np.empty((0, *array.shape[1:]), dtype=array.dtype))
    return {
        "format": FORMAT,
        "filled": used,
        "arrays": {n: {"shape": list(a.shape), "dtype": a.dtype.str} for n, a in arrays.items()},
        "chunks": chunks,
        "buffer": base64.b64encode(pickle.dumps(skeleton, protocol=4)).decode("ascii"),
    }


def load_buffer(manifest: dict[str, Any], folder: Path) -> Any:
    """The buffer a `store_buffer` manifest describes, its rows read back from `folder`."""
    fix = "Park the run again from the checkout it trains in, or train it again."
    if manifest.get("format") != FORMAT:
        raise FileFormatError(
            f"Replay manifest of format {manifest.get('format')!r} in {folder}; this advgame "
            f"reads format {FORMAT}. {fix}",
            path=str(folder),
        )
    buffer = pickle.loads(base64.b64decode(manifest["buffer"]))  # our own file, as SB3 pickles
    names = list(manifest["arrays"])
    full = {
        n: np.zeros(spec["shape"], dtype=np.dtype(spec["dtype"]))
        for n, spec in manifest["arrays"].items()
    }
    covered = 0
    for chunk in manifest["chunks"]:
        path = folder / chunk["file"]
        if not path.is_file():
            raise FileFormatError(f"Replay chunk {path} is missing. {fix}", path=str(path))
        start, end = int(chunk["start"]), int(chunk["end"])
        if start != covered:
            raise FileFormatError(f"Replay chunks in {folder} leave a gap at row {covered}. {fix}")
        for name, rows in _read_chunk(path, names).items():
            full[name][start:end] = rows
        covered = end
    if covered != int(manifest["filled"]):
        raise FileFormatError(
            f"Replay chunks in {folder} hold {covered} rows, the buffer {manifest['filled']}. {fix}"
        )
    for name, array in full.items():
        _put(buffer, name, array)
    return buffer
