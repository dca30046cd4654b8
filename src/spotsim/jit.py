"""The one switch for compiled kernels: numba's `njit`, with its compilation cached on disk.

The contact kernels loop over sphere pairs; numba compiles them once and later processes load
them from the cache in milliseconds. Numba checks a cached kernel against its own source file
only, not against the kernels it calls from other files, so the cache lives in a directory
named by a digest of every source file that defines kernels: any edit to one starts a fresh
cache.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

import numba


def add_sources(digest, root: Path, paths) -> None:
    """Add each of `paths` (files under `root`) to the hash `digest`: its path relative to
    root, then its bytes."""
    for path in paths:
        digest.update(path.relative_to(root).as_posix().encode())
        digest.update(path.read_bytes())


def _cache_dir() -> str:
    package = Path(__file__).resolve().parent
    digest = hashlib.sha256()
    # kernels call only kernels, so the files that define them are all they read
    add_sources(digest, package, [f for f in sorted(package.rglob("*.py")) if b"@njit" in f.read_bytes()])
    base = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "spotsim" / "numba"
    return str(base / digest.hexdigest()[:16])


if not os.environ.get("NUMBA_CACHE_DIR"):  # a directory the user chose wins
    numba.config.CACHE_DIR = _cache_dir()

#: Compiled, cached, and bit-for-bit IEEE arithmetic (no fast-math reassociation): the culled
#: and the literal searches must give identical forces.
njit = numba.njit(cache=True, fastmath=False, nogil=True)
#: ... and compiled into each caller (numba IR inlining), for small helpers called inside the
#: stages' loops: their arguments' reference counts then fall where numba's pruning removes them.
njit_inline = numba.njit(cache=True, fastmath=False, nogil=True, inline="always")

