"""numba as rkhp compiles with it: the cache folder, the compile settings, and numba itself with
rkhp's patches (`rkhp.taylor.numba_patches`).

numba checks only the file that defines a cached function (a hash of its content), not the files
whose functions it calls: after an edit of `rkhp/taylor/interpreter.py`, the cached engine would
still run the old interpreter. So the cache lives in a user folder named by a hash of every
compiled source (`rkhp/taylor/*.py` and `rkhp/integrators/*.py`, read as files, not imported)
and of the numba and llvmlite versions: $XDG_CACHE_HOME/rkhp/numba/<hash> (default
~/.cache/rkhp/numba/<hash>). Inside it a module's kernels are found by its package folder's name,
not by its path on disk (`rkhp.taylor.numba_patches.SourcesLocator`), so every checkout or
installation of the same sources shares one compile. A NUMBA_CACHE_DIR set by the user is
respected (with numba's own locator). rkhp never sets numba's cache folder
(`numba.config.CACHE_DIR`): other numba functions of the process are cached where numba puts
them. A folder that cannot be used is said once and replaced by a folder of the user's in the
temporary folder, and damaged cache files or failed saves cost a compile, never a run
(`rkhp.taylor.kernel_cache`).

Every compiled module takes numba (``from .compiler import numba as nb``) and its settings from
here. numba is imported, rkhp's cache folder chosen and every patch of rkhp applied
(`rkhp.taylor.numba_patches.apply`) when the first compiled module takes it, before it defines
its first kernel (`__getattr__`); importing rkhp or this module patches nothing.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import re
import shutil
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import NamedTuple

from .kernel_cache import usable_folder

#: the folders whose *.py files are compiled by numba (their hash names the cache folder)
COMPILED_SOURCES = ("taylor", "integrators")


#: the rkhp package folder
PACKAGE = Path(__file__).resolve().parent.parent
#: the distributions whose versions name the cache folder with the sources (numba discards an index
#: written by another numba version: two environments sharing a folder would recompile in turn)
COMPILER_DISTRIBUTIONS = ("numba", "llvmlite")


def cache_dir() -> Path:
    """rkhp's numba cache folder: named by a hash of the compiled sources and of the versions of
    `COMPILER_DISTRIBUTIONS` (read from their metadata, not imported)."""
    digest = hashlib.sha256()
    for folder in COMPILED_SOURCES:
        for path in sorted((PACKAGE / folder).glob("*.py")):
            digest.update(f"{folder}/{path.name}".encode())
            digest.update(path.read_bytes())
    for name in COMPILER_DISTRIBUTIONS:
        try:
            digest.update(f"{name}=={version(name)}".encode())
        except PackageNotFoundError:  # a numba run from its source tree: the sources name the folder
            digest.update(f"{name}==?".encode())
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return base / "rkhp" / "numba" / digest.hexdigest()[:16]


#: the name `cache_dir` gives a cache folder: 16 hex digits of the hash
CACHE_FOLDER_NAME = re.compile(r"[0-9a-f]{16}")


class Pruned(NamedTuple):
    """The cache folders of other versions that `prune_other_versions` removed, and the bytes
    their files held."""

    folders: tuple[str, ...]
    bytes: int


def other_versions(current: Path) -> list[Path]:
    """The cache folders beside ``current`` (a `cache_dir`) that other versions of the compiled
    sources or of the compiler named: folders (not links) whose names have the form of
    `cache_dir`'s, other than ``current``."""
    root = current.parent
    if not root.is_dir():
        return []
    return sorted(path for path in root.iterdir()
                  if path.name != current.name and CACHE_FOLDER_NAME.fullmatch(path.name)
                  and path.is_dir() and not path.is_symlink())


def folder_bytes(folder: Path) -> int:
    """The bytes of the files under ``folder`` (links not followed; a file removed meanwhile
    counts 0)."""
    total = 0
    for top, _, names in os.walk(folder):
        for name in names:
            with contextlib.suppress(FileNotFoundError):
                total += os.lstat(os.path.join(top, name)).st_size
    return total


def prune_other_versions(current: Path) -> Pruned:
    """Remove the cache folders of other versions (`other_versions`): each version of the
    sources or of numba compiles into a folder of its own, and nothing else removes the old ones.
    An environment still running another version compiles it again on its next run. A folder
    that cannot be removed: OSError naming it and how many were removed before it."""
    folders = other_versions(current)
    size = sum(folder_bytes(folder) for folder in folders)
    for done, folder in enumerate(folders):
        try:
            shutil.rmtree(folder)
        except FileNotFoundError:
            continue  # removed meanwhile (another process pruning)
        except OSError as exc:
            raise OSError(exc.errno, f"cannot remove the cache folder {folder} ({exc.strerror or exc}); "
                          f"{done} of {len(folders)} removed before it") from None
    return Pruned(tuple(str(folder) for folder in folders), size)


NJIT = dict(cache=True, nogil=True, fastmath=False, error_model="numpy")
"""Every compiled function: cached on disk, no GIL, IEEE arithmetic, numpy's error model.
Calls between compiled functions pass integers as np.int64(...), never as bare literals: numba
compiles a separate specialisation for every literal value (jet_mul once per degree)."""
NJIT_NORC = dict(NJIT, _nrt=False)
"""Kernels of the step loop that allocate nothing: compiled without numba's reference counting
(numba's incref/decref of every array argument at every call is a sizeable part of a step). A
function compiled so may only call functions that allocate nothing, or ones that set NJIT_NRT:
callees without an explicit setting inherit the caller's."""
NJIT_NRT = dict(NJIT, _nrt=True)
"""Functions that allocate and are called from NJIT_NORC kernels (e.g. in rkhp.taylor.composites)."""


def is_cached(kernel, signature: str | None = None) -> bool:
    """Whether numba's disk cache holds a fresh compiled version of ``kernel`` (a dispatcher
    compiled with ``cache=True``): its index file exists, is of this numba version and matches the
    stamp of the source file (numba recompiles otherwise). Reads numba's cache index the way
    numba does on a call (``FunctionCache``'s index file), so a call after True loads, not compiles.
    With ``signature``, only a version whose argument types, as numba writes them, contain that
    text counts (a tape class's name and "(": the kernel for that class of tapes).
    """
    cache = getattr(kernel, "_cache", None)
    index = getattr(getattr(cache, "_cache_file", None), "_load_index", None)
    if index is None:  # not a caching dispatcher (or numba's internals moved): nothing to announce
        return True
    try:
        entries = index()
    except Exception:  # an index numba cannot read (truncated, foreign pickle): numba recompiles
        return False
    if signature is None:
        return bool(entries)
    return any(signature in str(key[0]) for key in entries)


#: what `__getattr__` serves: numba, numba's `overload`, and rkhp's cache folder as numba uses it
#: (None: the user's NUMBA_CACHE_DIR), `cache_dir` or where it cannot be used the fallback of
#: `rkhp.taylor.kernel_cache.usable_folder`
PATCHED = ("numba", "overload", "RKHP_CACHE_DIR")


def __getattr__(name: str):
    """numba for rkhp's compiled modules (and `overload`, `RKHP_CACHE_DIR`, see `PATCHED`): at the
    first request, numba imported, rkhp's cache folder chosen and every patch applied
    (`rkhp.taylor.numba_patches.apply`); then module attributes like any other."""
    if name not in PATCHED:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    import numba
    from numba.extending import overload

    from . import numba_patches

    folder = None if numba.config.CACHE_DIR else str(usable_folder(cache_dir()).path)
    numba_patches.apply(folder, tuple(str(PACKAGE / source) for source in COMPILED_SOURCES))
    globals().update(numba=numba, overload=overload, RKHP_CACHE_DIR=folder)
    return globals()[name]


__all__ = ["cache_dir", "Pruned", "other_versions", "folder_bytes", "prune_other_versions", "is_cached",
           "NJIT", "NJIT_NORC", "NJIT_NRT", *PATCHED]
