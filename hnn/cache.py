"""Datasets cached as ``.npz`` files keyed by a hash of every parameter that made them.

    data = get_cached_dataset(save_dir, "3body", params, build)

The file name holds a hash of the params (seed included) and the file stores the params as
JSON beside the arrays, so a cache can never be silently reused for other params. The data
come back with ``cache_key``, the file's name, which a run records in its args.json.
"""
from __future__ import annotations

import hashlib
import json
import time
import warnings
from pathlib import Path
from typing import Callable

import numpy as np

from .io import atomic_write

_PARAMS_KEY = "__params__"


def _canonical(params: dict) -> dict:
    """``params`` as JSON would give them back (tuples become lists), so stored and requested compare equal."""
    return json.loads(json.dumps(params, sort_keys=True))


def cache_path(path_dir, name: str, params: dict) -> Path:
    """``<path_dir>/<name>-<12 hex digits of the SHA-256 of the params as JSON>.npz``."""
    text = json.dumps(_canonical(params), sort_keys=True, separators=(",", ":"))
    return Path(path_dir) / f"{name}-{hashlib.sha256(text.encode()).hexdigest()[:12]}.npz"


def _differences(stored: dict, wanted: dict) -> list[str]:
    out = []
    for key in sorted(set(stored) | set(wanted)):
        if key not in stored:
            out.append(f"{key} (absent in the cache, requested {wanted[key]!r})")
        elif key not in wanted:
            out.append(f"{key} (cached {stored[key]!r}, not requested)")
        elif stored[key] != wanted[key]:
            out.append(f"{key} (cached {stored[key]!r}, requested {wanted[key]!r})")
    return out


def _load(path: Path) -> tuple[dict, dict]:
    """``(params, arrays)`` of a cache file; raises on anything unreadable."""
    with np.load(path, allow_pickle=False) as f:
        params = json.loads(str(f[_PARAMS_KEY]))
        data = {k: f[k] for k in f.files if k != _PARAMS_KEY}
    return params, {k: v.item() if v.ndim == 0 else v for k, v in data.items()}


def _save(path: Path, params: dict, data: dict) -> None:
    arrays = {}
    for key, value in data.items():
        arr = np.asarray(value)
        if arr.dtype == object or key == _PARAMS_KEY:
            raise TypeError(f"cannot cache {key!r}: only numeric arrays and scalars are stored")
        arrays[key] = arr
    arrays[_PARAMS_KEY] = np.array(json.dumps(params, sort_keys=True))

    def write(tmp):
        with open(tmp, "wb") as f:   # a file object: np.savez would append .npz to a bare name
            np.savez(f, **arrays)
    atomic_write(path, write)


def get_cached_dataset(path_dir, name: str, params: dict, build: Callable[[], dict],
                       describe: Callable[[dict], str] | None = None) -> dict:
    """The dataset ``build()`` makes for ``params``, cached in ``cache_path(path_dir, name, params)``.

    The file name holds a hash of all the params (seed included) and the file holds the params
    themselves as JSON. A file whose stored params differ from ``params`` (a warning names the
    keys), or which cannot be read (a warning says why), is rebuilt and overwritten. With no
    file for these params, a message names the params in which the nearest other cache of
    ``name`` differs. ``build`` returns numeric arrays and scalars; the cache is written
    atomically and scalars come back as Python numbers either way, with ``cache_key``, the
    file's name (``<name>-<hash>.npz``).

    Args:
        describe: ``data -> str`` for the one-line message printed after a build.
    """
    wanted = _canonical(params)
    path = cache_path(path_dir, name, wanted)
    if path.exists():
        try:
            stored, data = _load(path)
        except Exception as err:  # noqa: BLE001 - any unreadable file is rebuilt
            warnings.warn(f"{name}: the cache {path} is unreadable ({type(err).__name__}: {err}); regenerating",
                          stacklevel=2)
        else:
            if stored == wanted:
                return {**data, "cache_key": path.name}
            warnings.warn(f"{name}: the cache {path} holds other params: {'; '.join(_differences(stored, wanted))}; "
                          "regenerating", stacklevel=2)
    else:
        nearest = None
        for other in sorted(Path(path_dir).glob(f"{name}-*.npz")):
            try:
                with np.load(other, allow_pickle=False) as f:
                    diff = _differences(json.loads(str(f[_PARAMS_KEY])), wanted)
            except Exception:  # noqa: BLE001 - an unreadable neighbour is not our concern here
                continue
            if nearest is None or len(diff) < len(nearest[1]):
                nearest = (other, diff)
        if nearest is not None:
            print(f"{name}: no cache for these params; the cached {nearest[0].name} differs in "
                  f"{'; '.join(nearest[1])}; generating")
    start = time.perf_counter()
    built = build()
    seconds = time.perf_counter() - start
    _save(path, wanted, built)
    data = {k: np.asarray(v).item() if np.ndim(v) == 0 else v for k, v in built.items()}
    what = describe(data) if describe else "the dataset"
    print(f"{name}: generated {what} in {seconds:.1f} s; cached at {path}")
    return {**data, "cache_key": path.name}
