"""Where numba keeps compiled code (`cache=True`): next to the modules when that folder is
writable, else in a user cache folder ($XDG_CACHE_HOME/rkhp/numba or ~/.cache/rkhp/numba).

Imported before numba by every compiled module, so the setting is in place when numba reads it.
"""

from __future__ import annotations

import os
from pathlib import Path


def _configure() -> None:
    if "NUMBA_CACHE_DIR" in os.environ:
        return
    here = Path(__file__).resolve().parent
    pycache = here / "__pycache__"
    target = pycache if pycache.exists() else here
    if os.access(target, os.W_OK):
        return
    base = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache"))
    os.environ["NUMBA_CACHE_DIR"] = str(base / "rkhp" / "numba")


_configure()

import numba  # noqa: E402  (after the cache folder is set)

__all__ = ["numba"]
