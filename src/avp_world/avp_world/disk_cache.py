"""Where the stack keeps on disk what every process would otherwise compute alike (look-up tables, generated
scenarios), and how a file gets there whole.

A cached file's name carries a digest of what it depends on: the caller's key, numpy's version and the source of
the modules that compute it, so a changed parameter or a changed computation never reads an old file. Writes go to a
temporary file renamed into place, so processes that write the same file at once leave one whole file. A cache is an
optimisation only: its users fall back to computing on any error reading or writing it.

The directory is ``$AVP_CACHE_DIR`` (set to the empty string to turn every cache off), else
``$XDG_CACHE_HOME/avp``, else ``~/.cache/avp``.
"""

from __future__ import annotations

import hashlib
import os
import tempfile
import zipfile
from collections.abc import Callable, Sequence
from pathlib import Path
from types import ModuleType
from typing import BinaryIO, TypeVar

import numpy as np

ENV = "AVP_CACHE_DIR"
T = TypeVar("T")
UNREADABLE = (OSError, ValueError, KeyError, TypeError, IndexError, EOFError, zipfile.BadZipFile)


def cache_dir() -> Path | None:
    """Where cached files are kept; None when ``$AVP_CACHE_DIR`` is set to the empty string (caches off)."""
    value = os.environ.get(ENV)
    if value is not None:
        return Path(value) if value else None
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "avp"


def digest(key: tuple, sources: Sequence[ModuleType | Path]) -> str:
    """24 hex digits of SHA-256 over ``repr(key)``, numpy's version and the source files of ``sources`` (modules or
    paths)."""
    h = hashlib.sha256(repr((key, np.__version__)).encode())
    for m in sources:
        h.update(Path(m.__file__ if isinstance(m, ModuleType) else m).read_bytes())
    return h.hexdigest()[:24]


def save_atomic(path: Path, write: Callable[[BinaryIO], None]) -> None:
    """``write`` the file at ``path`` through a temporary file in its directory renamed into place. OSError (a
    read-only or full disk) leaves no file and is left to the caller."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}-", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            write(f)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def cached(stem: str, suffix: str, key: tuple, sources: Sequence[ModuleType | Path], read: Callable[[Path], T | None],
           build: Callable[[], T], write: Callable[[BinaryIO, T], None], keep: Callable[[T], bool] | None = None) -> T:
    """What ``build()`` returns for ``key``: ``read`` from ``<dir>/<stem>-<digest><suffix>`` when that gives a whole
    value (None, or an error of :data:`UNREADABLE`: absent, cut short or not ours), else built and ``write``-n there
    (unless ``keep`` says no). With the cache off, or the disk failing, simply built."""
    d = cache_dir()
    if d is None:
        return build()
    try:
        path = d / f"{stem}-{digest(key, sources)}{suffix}"
    except OSError:
        return build()
    try:
        value = read(path)
        if value is not None:
            return value
    except UNREADABLE:
        pass
    value = build()
    if keep is None or keep(value):
        try:
            save_atomic(path, lambda f: write(f, value))
        except OSError:
            pass  # a read-only or full disk: the value is still right, only not kept
    return value


__all__ = ["ENV", "UNREADABLE", "cache_dir", "cached", "digest", "save_atomic"]
