"""A disk cache of look-up tables that every process would otherwise build alike (the Reeds-Shepp length table of
:func:`avp_search.heuristic.rs_length_table`: about 0.6 s of CPU at each planner or prediction node's start).

A table is stored as ``<dir>/<name>-<digest>.npy`` in the stack's cache directory (:mod:`avp_world.disk_cache`:
``$AVP_CACHE_DIR``, the empty string turning it off, else ``$XDG_CACHE_HOME/avp``, else ``~/.cache/avp``); the
digest covers the table's parameters, the source of the modules that compute it and numpy's version, so a changed
parameter or a changed computation never reads an old file. A file that does not read back as the expected shape
and dtype, or holds a non-finite value, is built anew and replaced. The cache is an optimisation only: any error
reading or writing it falls back to building.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from types import ModuleType

import numpy as np

from avp_world.disk_cache import ENV, cache_dir, cached


def cached_table(name: str, key: tuple, modules: Sequence[ModuleType], shape: tuple[int, ...],
                 build: Callable[[], np.ndarray]) -> np.ndarray:
    """The float32 table ``build()`` returns for ``key``, read from the cache when a whole one is there (else built
    and stored). ``modules``: the modules whose source computes it (part of the file's digest)."""

    def read(path):
        table = np.load(path, allow_pickle=False)
        whole = table.shape == tuple(shape) and table.dtype == np.float32 and np.isfinite(table).all()
        return table if whole else None

    return cached(name, ".npy", key, modules, read, build, lambda f, table: np.save(f, table, allow_pickle=False))


__all__ = ["ENV", "cache_dir", "cached_table"]
