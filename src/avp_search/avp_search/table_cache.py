"""A disk cache of look-up tables that every process would otherwise build alike (the Reeds-Shepp length table of
:func:`avp_search.heuristic.rs_length_table`: about 0.6 s of CPU at each planner or prediction node's start).

A table is stored as ``<dir>/<name>-<digest>.npy``; the digest covers the table's parameters, the source of the
modules that compute it and numpy's version, so a changed parameter or a changed computation never reads an old
file. A file that does not read back as the expected shape and dtype, or holds a non-finite value, is built anew
and replaced. Writes go to a temporary file renamed into place, so processes that build the same table at once
leave one whole file. The cache is an optimisation only: any error reading or writing it falls back to building.

The directory is ``$AVP_CACHE_DIR`` (set to the empty string to turn the cache off), else
``$XDG_CACHE_HOME/avp``, else ``~/.cache/avp``.
"""

from __future__ import annotations

import hashlib
import os
import tempfile
from collections.abc import Callable, Sequence
from pathlib import Path
from types import ModuleType

import numpy as np

ENV = "AVP_CACHE_DIR"


def cache_dir() -> Path | None:
    """Where tables are kept; None when ``$AVP_CACHE_DIR`` is set to the empty string (cache off)."""
    value = os.environ.get(ENV)
    if value is not None:
        return Path(value) if value else None
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "avp"


def _digest(key: tuple, modules: Sequence[ModuleType]) -> str:
    h = hashlib.sha256(repr((key, np.__version__)).encode())
    for m in modules:
        h.update(Path(m.__file__).read_bytes())
    return h.hexdigest()[:24]


def cached_table(name: str, key: tuple, modules: Sequence[ModuleType], shape: tuple[int, ...],
                 build: Callable[[], np.ndarray]) -> np.ndarray:
    """The float32 table ``build()`` returns for ``key``, read from the cache when a whole one is there (else built
    and stored). ``modules``: the modules whose source computes it (part of the file's digest)."""
    d = cache_dir()
    if d is None:
        return build()
    try:
        path = d / f"{name}-{_digest(key, modules)}.npy"
    except OSError:
        return build()
    try:
        table = np.load(path, allow_pickle=False)
        if table.shape == tuple(shape) and table.dtype == np.float32 and np.isfinite(table).all():
            return table
    except (OSError, ValueError, EOFError):
        pass  # absent, cut short or not an .npy: build it
    table = build()
    try:
        d.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{name}-", suffix=".tmp", dir=d)
        try:
            with os.fdopen(fd, "wb") as f:
                np.save(f, table, allow_pickle=False)
            os.replace(tmp, path)
        finally:
            if os.path.exists(tmp):
                os.unlink(tmp)
    except OSError:
        pass  # a read-only or full disk: the table is still right, only not kept
    return table
