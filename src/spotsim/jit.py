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
import numba.core.event


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

class _FirstCompile(numba.core.event.Listener):
    """Calls its `say()` at the first compilation it hears of, once."""

    say = None

    def on_start(self, event) -> None:
        if self.say is not None:
            say, self.say = self.say, None
            say()

    def on_end(self, event) -> None:
        pass


_first_compile = _FirstCompile()
numba.core.event.register("numba:compile", _first_compile)


def announce_compiling(say) -> None:
    """Call `say()` when the next kernel this process needs is compiled rather than loaded
    from the cache (numba's `numba:compile` event fires only then): the first run after an
    install or an edit of the kernels, which takes minutes. Once; a later call replaces a
    `say` not yet called (None: say nothing)."""
    _first_compile.say = say


#: Compiled, cached, and bit-for-bit IEEE arithmetic (no fast-math reassociation): the culled
#: and the literal searches must give identical forces.
njit = numba.njit(cache=True, fastmath=False, nogil=True)
#: ... and compiled into each caller (numba IR inlining), for small helpers called inside the
#: stages' loops: their arguments' reference counts then fall where numba's pruning removes them.
njit_inline = numba.njit(cache=True, fastmath=False, nogil=True, inline="always")

