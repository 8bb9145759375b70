"""Point numba's on-disk cache at a directory keyed by this package's sources.

numba invalidates a cached function when *its own* file changes, but not when
a function it calls (and inlined) changes in another file, so an edited or
upgraded package could run stale machine code.  Keying the cache directory on
a hash of all package sources rules that out.  A user-set
``NUMBA_CACHE_DIR`` is respected.  Imported by :mod:`frictionlab.model._jit` just before
numba itself (on the first use of a compiled kernel).
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path


def _source_hash() -> str:
    h = hashlib.sha1()
    root = Path(__file__).resolve().parent
    for path in sorted(root.rglob("*.py")):
        h.update(path.relative_to(root).as_posix().encode())
        h.update(path.read_bytes())
    return h.hexdigest()[:16]


def _prune(base: Path, keep: Path, max_age_s: float = 2 * 86400) -> None:
    """Remove cache directories of other source versions unused for two days."""
    import shutil
    import time

    try:
        for d in base.glob("numba-*"):
            if d != keep and time.time() - d.stat().st_mtime > max_age_s:
                shutil.rmtree(d, ignore_errors=True)
    except OSError:
        pass


if "NUMBA_CACHE_DIR" not in os.environ:
    _base = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "frictionlab"
    _dir = _base / f"numba-{_source_hash()}"
    os.environ["NUMBA_CACHE_DIR"] = str(_dir)
    _prune(_base, _dir)
