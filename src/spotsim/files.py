"""Writing result files so that a kill at any moment leaves each file whole or absent, and
checking before a run that its results fit on their disk."""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path

from .errors import SpotsimError


def atomic_write(path: Path, text: str) -> None:
    """Write `text` to a temporary file beside `path`, then rename it over `path`: a reader
    (or a kill) sees the old file, the new one, or none; never half of one."""
    atomic(path, lambda f: f.write(text.encode()))


def atomic(path: Path, write) -> None:
    """Call `write(f)` on a binary file that becomes `path` only once `write` returns; on any
    failure the temporary file is removed and `path` is left as it was."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.")
    try:
        with os.fdopen(fd, "wb") as f:
            write(f)
        os.chmod(tmp, 0o644)  # a result to read and share (mkstemp makes it private)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def prepare(out_dir: str | Path, summary: str, need_bytes: float = 0.0) -> Path:
    """Make `out_dir`, remove a previous result's `summary` file (so that a run or a study
    killed before it writes its own leaves none beside its new files), and check that
    `need_bytes` fit on its disk: SpotsimError before anything runs if not."""
    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
        (out / summary).unlink(missing_ok=True)
    except OSError as e:
        raise SpotsimError(f"{out}: cannot write results: {e.strerror}") from e
    check_space(out, need_bytes, "the results")
    return out


def check_space(out: Path, need_bytes: float, what: str) -> None:
    """SpotsimError if `out`'s disk has less than `need_bytes` free (checked before a run, so
    that a full disk is found before the computing is spent)."""
    free = shutil.disk_usage(out).free
    if free < need_bytes:
        raise SpotsimError(f"{out}: {what} need about {_mb(need_bytes)}, and its disk has {_mb(free)} free")


def _mb(n: float) -> str:
    return f"{n / 1e6:.3g} MB"


def save_figure(fig, path: Path, dpi: int = 110) -> None:
    """A matplotlib figure as a PNG at `path`, whole or not at all (`atomic`)."""
    atomic(path, lambda f: fig.savefig(f, format="png", dpi=dpi))
