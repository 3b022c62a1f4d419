"""numba as rkhp compiles with it: the cache folder and the compile settings.

numba checks only the time stamp of the file that defines a cached function, not of the files
whose functions it calls: after an edit of `rkhp/taylor/interpreter.py`, the cached engine would
still run the old interpreter. So the cache lives in a user folder named by a hash of every
compiled source (`rkhp/taylor/*.py` and `rkhp/integrators/*.py`, read as files, not imported):
$XDG_CACHE_HOME/rkhp/numba/<hash> (default ~/.cache/rkhp/numba/<hash>). A NUMBA_CACHE_DIR set by
the user is respected. Every compiled module imports numba and its settings from here.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

#: the folders whose *.py files are compiled by numba (their hash names the cache folder)
COMPILED_SOURCES = ("taylor", "integrators")


def cache_dir() -> Path:
    package = Path(__file__).resolve().parent.parent
    digest = hashlib.sha256()
    for folder in COMPILED_SOURCES:
        for path in sorted((package / folder).glob("*.py")):
            digest.update(f"{folder}/{path.name}".encode())
            digest.update(path.read_bytes())
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return base / "rkhp" / "numba" / digest.hexdigest()[:16]


import copy  # noqa: E402

import numba  # noqa: E402
from numba.core import inline_closurecall  # noqa: E402
from numba.extending import overload  # noqa: E402

if not os.environ.get("NUMBA_CACHE_DIR"):
    numba.config.CACHE_DIR = str(cache_dir())


class _OneMemo:
    """`copy.deepcopy` with one memo for everything copied while inlining one call site."""

    def __init__(self):
        self.memo: dict = {}

    def deepcopy(self, x, memo=None):
        return copy.deepcopy(x, self.memo if memo is None else memo)


def _inline_with_one_memo(inline_ir):
    """numba's inliner (`InlineWorker.inline_ir`, every `inline="always"` call site) deep-copies
    the callee's IR block by block, each block with a memo of its own, so each block copies the
    callee's whole variable scope again: the copy is quadratic in the size of the inlined function
    (numba issue #8989), and was a quarter of the engine's cold compile (docs/engine.md "Compile
    time"). With one memo per call site the blocks share one copy of the scope, as the blocks of
    the callee share one scope: the same IR, and the same machine code (results unchanged
    bitwise). The module's `copy` is swapped for the call only (numba compiles under its global
    compiler lock, one function at a time)."""

    def inline_ir_one_memo(self, *args, **kwargs):
        inline_closurecall.copy = _OneMemo()
        try:
            return inline_ir(self, *args, **kwargs)
        finally:
            inline_closurecall.copy = copy

    inline_ir_one_memo.one_memo = True
    return inline_ir_one_memo


_worker = inline_closurecall.InlineWorker
if getattr(inline_closurecall, "copy", None) is copy and not hasattr(_worker.inline_ir, "one_memo"):
    _worker.inline_ir = _inline_with_one_memo(_worker.inline_ir)

NJIT = dict(cache=True, nogil=True, fastmath=False, error_model="numpy")
"""Every compiled function: cached on disk, no GIL, IEEE arithmetic, numpy's error model.
Calls between compiled functions pass integers as np.int64(...), never as bare literals: numba
compiles a separate specialisation for every literal value (measured: 10 of jet_mul)."""
NJIT_NORC = dict(NJIT, _nrt=False)
"""Kernels of the step loop that allocate nothing: compiled without numba's reference counting
(its incref/decref of every array argument was about a fifth of a step). A function compiled so
may only call functions that allocate nothing, or ones that set NJIT_NRT: callees without an
explicit setting inherit the caller's."""
NJIT_NRT = dict(NJIT, _nrt=True)
"""Functions that allocate and are called from NJIT_NORC kernels (e.g. crb_coef's closed form)."""



def is_cached(kernel) -> bool:
    """Whether numba's disk cache holds a fresh compiled version of ``kernel`` (a dispatcher
    compiled with ``cache=True``): its index file exists, is of this numba version and matches the
    stamp of the source file (numba recompiles otherwise). Reads numba's cache index the way
    numba does on a call (``FunctionCache``'s index file), so a call after True loads, not compiles.
    """
    cache = getattr(kernel, "_cache", None)
    index = getattr(getattr(cache, "_cache_file", None), "_load_index", None)
    if index is None:  # not a caching dispatcher (or numba's internals moved): nothing to announce
        return True
    try:
        return bool(index())
    except Exception:  # an index numba cannot read (truncated, foreign pickle): numba recompiles
        return False


__all__ = ["numba", "overload", "cache_dir", "is_cached", "NJIT", "NJIT_NORC", "NJIT_NRT"]
