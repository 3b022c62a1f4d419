"""Where numba keeps compiled code (`cache=True`).

numba checks only the time stamp of the file that defines a cached function, not of the files
whose functions it calls: after an edit of `jets.py`, the cached engine would still run the old
interpreter. So the cache lives in a user folder named by a hash of the compiled sources
(`rkhp/integrators/*.py` and `rkhp/systems/tape.py`):
$XDG_CACHE_HOME/rkhp/numba/<hash> (default ~/.cache/rkhp/numba/<hash>). A NUMBA_CACHE_DIR set by
the user is respected. Every compiled module imports numba from here.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path


def cache_dir() -> Path:
    here = Path(__file__).resolve().parent
    digest = hashlib.sha256()
    for path in sorted(here.glob("*.py")) + [here.parent / "systems" / "tape.py"]:
        digest.update(path.name.encode())
        digest.update(path.read_bytes())
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return base / "rkhp" / "numba" / digest.hexdigest()[:16]


import numba  # noqa: E402

if not os.environ.get("NUMBA_CACHE_DIR"):
    numba.config.CACHE_DIR = str(cache_dir())

__all__ = ["numba", "cache_dir"]
