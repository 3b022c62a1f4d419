"""numba as rkhp compiles with it: the cache folder and the compile settings.

numba checks only the file that defines a cached function (a hash of its content), not the files
whose functions it calls: after an edit of `rkhp/taylor/interpreter.py`, the cached engine would
still run the old interpreter. So the cache lives in a user folder named by a hash of every
compiled source (`rkhp/taylor/*.py` and `rkhp/integrators/*.py`, read as files, not imported)
and of the numba and llvmlite versions: $XDG_CACHE_HOME/rkhp/numba/<hash> (default
~/.cache/rkhp/numba/<hash>). Inside it a module's kernels are found by its package folder's name,
not by its path on disk (`SourcesLocator`), so every checkout or installation of the same sources
shares one compile. A NUMBA_CACHE_DIR set by the user is respected (with numba's own locator).
A folder that cannot be used is said once and replaced by a folder of the user's in the temporary
folder, and damaged cache files or failed saves cost a compile, never a run
(`rkhp.taylor.kernel_cache`). Every compiled module imports numba and its settings from here.

numba's own writes to that cache are made safe for processes compiling side by side
(`_save_locked`), its inliner cheaper (`_cheap_inlining`), and its cache shared by every copy of
the same sources (`SourcesLocator`); each patch is applied only to the form of numba it was
checked on (tests/test_dependencies.py fails loudly on another).
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


import copy  # noqa: E402

try:
    import fcntl
except ImportError:  # not POSIX: numba's saves stay unlocked, and rkhp compiles in one process
    fcntl = None

import numba  # noqa: E402
from numba.core import caching, inline_closurecall  # noqa: E402
from numba.extending import overload  # noqa: E402

from .kernel_cache import make_cache_robust, usable_folder  # noqa: E402

#: rkhp's cache folder when numba uses it (None: the user's NUMBA_CACHE_DIR): `cache_dir`, or
#: where it cannot be used, the fallback of `rkhp.taylor.kernel_cache.usable_folder`
RKHP_CACHE_DIR = None if os.environ.get("NUMBA_CACHE_DIR") else str(usable_folder(cache_dir()).path)
if RKHP_CACHE_DIR is not None:
    numba.config.CACHE_DIR = RKHP_CACHE_DIR
make_cache_robust(caching)


class _OneMemo:
    """`copy.deepcopy` with one memo for everything copied while inlining one call site."""

    def __init__(self):
        self.memo: dict = {}

    def deepcopy(self, x, memo=None):
        return copy.deepcopy(x, self.memo if memo is None else memo)


class _NoCopy:
    """`copy.deepcopy` for an IR that nothing else holds: the object itself."""

    @staticmethod
    def deepcopy(x, memo=None):
        return x


#: the names `InlineWorker.inline_function` uses, in numba's form that the patch was checked on:
#: build the callee's IR, then call `inline_ir` once
INLINE_FUNCTION_NAMES = ("run_untyped_passes", "__code__", "co_freevars", "inline_ir")


def _code_objects(code):
    """``code`` and the code objects nested in it (local functions), depth first."""
    yield code
    for const in code.co_consts:
        if hasattr(const, "co_names"):
            yield from _code_objects(const)


def _deepcopy_users(module) -> list[str]:
    """Qualified names of the functions of ``module`` (its classes' methods included) whose code
    calls ``deepcopy`` on a global name."""
    functions = []
    for value in list(vars(module).values()):
        if isinstance(value, type) and value.__module__ == module.__name__:
            functions += [f for f in vars(value).values() if hasattr(f, "__code__")]
            functions += getattr(value, "rkhp_originals", ())  # numba's own, under this patch
        elif hasattr(value, "__code__") and value.__module__ == module.__name__:
            functions.append(value)
    return sorted(code.co_qualname for f in functions for code in _code_objects(f.__code__)
                  if "deepcopy" in code.co_names)


def inlining_precondition(module=inline_closurecall) -> list[str]:
    """What `_cheap_inlining` expects of numba's inliner module and does not find (empty: all).

    The patch swaps the module's global ``copy`` during `InlineWorker.inline_ir`, so ``copy``
    must be the standard module and its only ``deepcopy`` the one copying the callee's IR
    (``inline_ir``'s local ``copy_ir``); it skips the copy of an IR that `inline_function` has just
    built, so that function must still be "build the IR, then `inline_ir` once"."""
    worker = module.InlineWorker
    inline_ir, inline_function = getattr(worker, "rkhp_originals", (worker.inline_ir, worker.inline_function))
    missing = []
    if getattr(module, "copy", None) is not copy:
        missing.append(f"{module.__name__}.copy is not the copy module")
    users = _deepcopy_users(module) if not missing else []
    if not missing and users != ["InlineWorker.inline_ir.<locals>.copy_ir"]:
        missing.append(f"deepcopy is called in {users or 'no function'}, not only in inline_ir's copy_ir")
    if getattr(inline_ir, "__qualname__", "") != "InlineWorker.inline_ir":
        missing.append("InlineWorker.inline_ir is not numba's own")
    if getattr(getattr(inline_function, "__code__", None), "co_names", ()) != INLINE_FUNCTION_NAMES:
        missing.append(f"InlineWorker.inline_function does not use exactly {INLINE_FUNCTION_NAMES}")
    return missing


def _cheap_inlining(worker) -> None:
    """Make numba's inlining of `inline="always"` functions cheaper, with the same result.

    At every call site numba's inliner (`InlineWorker.inline_ir`) deep-copies the callee's IR
    twice (a copy to rewrite and an untouched copy to return), block by block with a memo per
    block, so each block copies the callee's whole variable scope again: quadratic in the size of
    the inlined function (numba issue #8989; docs/engine.md "Compile time"). Here the copies share
    one memo (the blocks of the copy share one scope, as the callee's do), and an IR that
    `InlineWorker.inline_function` has just built for this one site (nothing else holds it, and
    numba's callers drop the returned copy) is not copied at all. The IR, the machine code and the
    results are the same (bitwise). numba's `copy` module is swapped for the call only (numba
    compiles under its global lock). Applied only when `inlining_precondition` finds numba's
    inliner in the form this was checked on (numba 0.68); tests/test_dependencies.py fails
    loudly otherwise."""
    inline_ir, inline_function = worker.inline_ir, worker.inline_function

    def inline_ir_cheaply(self, *args, **kwargs):
        fresh, self._rkhp_fresh_ir = getattr(self, "_rkhp_fresh_ir", False), False
        inline_closurecall.copy = _NoCopy() if fresh else _OneMemo()
        try:
            return inline_ir(self, *args, **kwargs)
        finally:
            inline_closurecall.copy = copy

    def inline_function_fresh(self, *args, **kwargs):
        self._rkhp_fresh_ir = True
        try:
            return inline_function(self, *args, **kwargs)
        finally:
            self._rkhp_fresh_ir = False

    worker.rkhp_originals = (inline_ir, inline_function)
    worker.inline_ir = inline_ir_cheaply
    worker.inline_function = inline_function_fresh
    worker.rkhp_cheap_inlining = True


if (not getattr(inline_closurecall.InlineWorker, "rkhp_cheap_inlining", False)
        and not inlining_precondition()):
    _cheap_inlining(inline_closurecall.InlineWorker)


#: the names numba's `IndexDataCacheFile.save` uses, in the form the locked save was checked on
#: (numba 0.68): load the index, pick a free data name, save the index, then the data
CACHE_SAVE_NAMES = ("_load_index", "KeyError", "set", "values", "itertools", "count", "_data_name",
                    "_save_index", "_save_data")
#: the lock file, one per cache folder of a source file
CACHE_LOCK_NAME = ".rkhp-save.lock"


def cache_save_precondition(module=caching) -> list[str]:
    """What `_locked_cache_saves` expects of numba's cache module and does not find (empty: all):
    `IndexDataCacheFile` with numba's own ``save`` of the form above and the helpers it calls,
    and POSIX file locks (``fcntl``)."""
    index_file = getattr(module, "IndexDataCacheFile", None)
    if index_file is None:
        return [f"{module.__name__} has no IndexDataCacheFile"]
    save = getattr(index_file, "rkhp_original_save", getattr(index_file, "save", None))
    missing = []
    if getattr(getattr(save, "__code__", None), "co_names", ()) != CACHE_SAVE_NAMES:
        missing.append(f"IndexDataCacheFile.save does not use exactly {CACHE_SAVE_NAMES}")
    missing += [f"IndexDataCacheFile has no {name}" for name in ("_load_index", "_save_index", "_save_data",
                                                                   "_data_name") if not hasattr(index_file, name)]
    if fcntl is None:
        missing.append("no fcntl (POSIX file locks) on this platform")
    return missing


def _free_data_name(cache_file, overloads: dict) -> str:
    """The first data file name that the index ``overloads`` does not use (numba's numbering)."""
    used = set(overloads.values())
    number = 1
    while cache_file._data_name(number) in used:
        number += 1
    return cache_file._data_name(number)


def _save_locked(cache_file, key, data) -> None:
    """numba's `IndexDataCacheFile.save` under an exclusive lock of the cache folder, data first.

    numba reads the index, picks a free data file name, writes the index, then the data. Two
    processes saving new versions of one function at once (``rkhp compile --jobs``, test processes,
    workers of a pool on a cold cache) can both pick the same name: one index entry then names the
    other process's machine code. Under the lock the read, the pick and both writes of one save
    happen alone; the data is written before the index names it, so a reader finds an entry only
    once its code is in place (both writes replace their file atomically, as numba's do)."""
    with open(os.path.join(cache_file._cache_path, CACHE_LOCK_NAME), "a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        overloads = cache_file._load_index()
        name = overloads.get(key) or _free_data_name(cache_file, overloads)
        cache_file._save_data(name, data)
        if overloads.get(key) != name:
            overloads[key] = name
            cache_file._save_index(overloads)


def _locked_cache_saves(index_file) -> None:
    index_file.rkhp_original_save = index_file.save
    index_file.save = _save_locked
    index_file.rkhp_locked_saves = True


if (not getattr(caching.IndexDataCacheFile, "rkhp_locked_saves", False)
        and not cache_save_precondition()):
    _locked_cache_saves(caching.IndexDataCacheFile)


def parallel_compiles_safe() -> bool:
    """Whether processes may compile into one cache side by side (numba's saves are locked)."""
    return bool(getattr(caching.IndexDataCacheFile, "rkhp_locked_saves", False))


def is_compiled_source(py_file: str) -> bool:
    """Whether ``py_file`` is one of rkhp's compiled sources (a .py file of `COMPILED_SOURCES`)."""
    path = Path(py_file).resolve()
    return path.suffix == ".py" and path.parent.name in COMPILED_SOURCES and path.parent.parent == PACKAGE


#: numba's locator of a user's cache folder, which `SourcesLocator` refines (a numba without it
#: fails `locator_precondition`, and the class is then never used)
_USER_FOLDER_LOCATOR = getattr(caching, "UserProvidedCacheLocator", object)


class SourcesLocator(_USER_FOLDER_LOCATOR):
    """numba's cache locator for rkhp's compiled sources: a module's kernels are kept in
    `RKHP_CACHE_DIR`/<its package folder> (``taylor``, ``integrators``), where numba's own locator
    names the folder by a hash of the source file's absolute path. `RKHP_CACHE_DIR` is named by the
    sources and the compiler's versions (`cache_dir`), and numba checks a cached function against
    a hash of its file's content, so another clone, another virtual environment or ``pip install
    .`` beside ``pip install -e .`` of the same sources loads what any of them compiled. Other
    functions, and every function while the cache is a user's NUMBA_CACHE_DIR, are left to numba's
    locators (`from_function` answers None). The folder is not tried for writing here, as numba's
    locators do before they answer: one that cannot be written was said once
    (`rkhp.taylor.kernel_cache.usable_folder`), and numba must then keep nothing rather than write
    into the sources' ``__pycache__``."""

    def __init__(self, py_func, py_file):
        super().__init__(py_func, py_file)
        self._cache_path = os.path.join(numba.config.CACHE_DIR, Path(py_file).resolve().parent.name)

    @classmethod
    def from_function(cls, py_func, py_file):
        if RKHP_CACHE_DIR is None or numba.config.CACHE_DIR != RKHP_CACHE_DIR or not is_compiled_source(py_file):
            return None
        return cls(py_func, py_file)


def locator_precondition(module=caching) -> list[str]:
    """What `SourcesLocator` expects of numba's cache module and does not find (empty: all):
    the list of locators that `CacheImpl` tries in turn, holding `UserProvidedCacheLocator`, and
    a source stamp that is a hash of the file's content (numba 0.68; a time stamp would differ
    between two copies of one file, and each would discard the other's index)."""
    impl = getattr(module, "CacheImpl", None)
    classes = getattr(impl, "_locator_classes", None)
    base = getattr(module, "UserProvidedCacheLocator", None)
    if not isinstance(classes, list) or base is None or base not in classes:
        return ["CacheImpl._locator_classes is not a list holding UserProvidedCacheLocator"]
    stamp = getattr(getattr(base, "get_source_stamp", None), "__code__", None)
    if stamp is None or "_hash_source_file" not in stamp.co_names:
        return ["UserProvidedCacheLocator.get_source_stamp does not hash the source file's content"]
    return []


if not locator_precondition() and SourcesLocator not in caching.CacheImpl._locator_classes:
    caching.CacheImpl._locator_classes.insert(0, SourcesLocator)


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


__all__ = ["numba", "overload", "cache_dir", "Pruned", "other_versions", "folder_bytes",
           "prune_other_versions", "is_cached", "inlining_precondition", "cache_save_precondition",
           "parallel_compiles_safe", "is_compiled_source", "SourcesLocator", "locator_precondition",
           "NJIT", "NJIT_NORC", "NJIT_NRT"]
