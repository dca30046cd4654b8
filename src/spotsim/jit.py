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


def _cache_dir() -> str:
    package = Path(__file__).resolve().parent
    digest = hashlib.sha256()
    for source in sorted(package.rglob("*.py")):
        text = source.read_bytes()
        if b"@njit" in text:  # kernels call only kernels, so these files are all they read
            digest.update(source.relative_to(package).as_posix().encode())
            digest.update(text)
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

