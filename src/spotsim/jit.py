"""The one switch for compiled kernels: numba's `njit`, with its compilation cached on disk.

The contact kernels loop over sphere pairs; numba compiles them once and later processes load
them from the cache in milliseconds. Numba checks a cached kernel against its own source file
only, not against the kernels it calls from other files, so the cache lives in a directory
named by a digest of every source file that defines kernels: any edit to one starts a fresh
cache. Each holds 100-300 MB, so the older ones are pruned (`prune_caches`).

A kernel compiles once per distinct type of its arguments, and a constant that one kernel
passes another is typed as its value (`Literal[bool](True)`; an omitted default is a type of
its own): a flag is therefore passed as `np.bool_(...)`, a plain boolean, so that one
compilation serves every caller (a cold start compiled `_articulated` four times, 35 s).
"""

from __future__ import annotations

import hashlib
import os
import shutil
import time
from pathlib import Path

import numba
import numba.core.event


def add_sources(digest, root: Path, paths) -> None:
    """Add each of `paths` (files under `root`) to the hash `digest`: its path relative to
    root, then its bytes."""
    for path in paths:
        digest.update(path.relative_to(root).as_posix().encode())
        digest.update(path.read_bytes())


#: The cache directories kept (`prune_caches`): the most recently used ones, the one in use
#: among them; an older one goes once it has not been used for CACHE_IDLE_S.
CACHES_KEPT = 3
CACHE_IDLE_S = 7 * 86_400.0
#: The file whose modification time is a cache directory's last use.
LAST_USED = "last_used"


def prune_caches(current: Path, kept: int = CACHES_KEPT, idle_s: float = CACHE_IDLE_S) -> list[Path]:
    """Mark the cache directory `current` used now, and remove those beside it beyond the
    `kept` most recently used (`current` among them) that no process has used for `idle_s`:
    every update of spotsim, or edit of a kernel, starts a new one. Returns those removed."""
    def last_use(d: Path) -> float:
        try:
            return (d / LAST_USED).stat().st_mtime
        except OSError:  # one made before its use was marked
            return d.stat().st_mtime

    current.mkdir(parents=True, exist_ok=True)
    (current / LAST_USED).touch()
    others = sorted((d for d in current.parent.iterdir() if d.is_dir() and d != current), key=last_use, reverse=True)
    now = time.time()
    removed = [d for d in others[kept - 1:] if now - last_use(d) > idle_s]
    for d in removed:
        shutil.rmtree(d, ignore_errors=True)
    return removed


def _cache_dir() -> Path:
    package = Path(__file__).resolve().parent
    digest = hashlib.sha256()
    # kernels call only kernels, so the files that define them are all they read
    add_sources(digest, package, [f for f in sorted(package.rglob("*.py")) if b"@njit" in f.read_bytes()])
    base = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "spotsim" / "numba"
    return base / digest.hexdigest()[:16]


if not os.environ.get("NUMBA_CACHE_DIR"):  # a directory the user chose wins
    numba.config.CACHE_DIR = str(_cache_dir())
    try:
        prune_caches(Path(numba.config.CACHE_DIR))
    except OSError:  # a cache numba cannot write either: it compiles without one
        pass


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

