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
#: ... and compiled into each caller (numba IR inlining): a call that passes a dozen arrays costs
#: a few hundred ns, a small kernel's arithmetic a few tens.
njit_inline = numba.njit(cache=True, fastmath=False, nogil=True, inline="always")


def direct(kernel):
    """A caller of `kernel` that finds its compiled version at the first call and calls it
    directly afterwards, skipping the dispatcher's type resolution.

    For the step's contact kernel (~40 arguments, three of them named tuples) that resolution
    cost ~30 us a call, a third of a step. Only for call sites whose argument types cannot
    change within a process: arrays of the model (fixed at build) and of the state (made by
    the kernels themselves), Python floats.
    """
    compiled = None

    def call(*args):
        nonlocal compiled
        if compiled is None:
            result = kernel(*args)  # compiles or loads it for these types
            compiled = kernel.overloads[tuple(kernel.typeof_pyval(a) for a in args)].entry_point
            return result
        return compiled(*args)

    call.__doc__ = kernel.__doc__
    return call
