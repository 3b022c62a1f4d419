"""Every patch rkhp makes to numba, applied together and once by `apply` (docs/engine.md "The
patches to numba").

`apply` runs when the first of rkhp's compiled modules takes numba from `rkhp.taylor.compiler`,
before that module defines its first kernel: numba fixes a cached function's locator when the
function is decorated, and loads, compiles and saves it at its first call. Importing rkhp, or
`rkhp.taylor.compiler` for its cache folders and settings, patches nothing. Each patch replaces
named pieces of numba and is applied only where numba has the form it was checked on (numba
0.68.1, the pin of constraints.txt): its precondition says what it misses, and
tests/test_dependencies.py fails loudly on another form or on other sources of what it replaces.

- `cheap_inlining` replaces `numba.core.inline_closurecall.InlineWorker.inline_ir` and
  `InlineWorker.inline_function`: the same IR, without the deep copies that make the compile
  time quadratic in the size of an inlined function;
- `locked_saves` replaces `numba.core.caching.IndexDataCacheFile.save`: processes compiling into
  one cache side by side lose no entry and never point one at another's machine code;
- `robust_cache` replaces `IndexDataCacheFile._load_index`, `Cache._load_overload` and
  `Cache.save_overload` (numba.core.caching): a damaged cache file is a miss and a failed save a
  warning (`rkhp.taylor.kernel_cache`), never an error;
- `sources_locator` puts `SourcesLocator` first in `numba.core.caching.CacheImpl._locator_classes`:
  rkhp's kernels are kept in rkhp's cache folder, shared by every copy of the same sources. It
  answers for rkhp's compiled sources only, and numba's cache folder setting
  (`numba.config.CACHE_DIR`, NUMBA_CACHE_DIR) is left as it is: every other function of the
  process is cached where numba puts it.

The first three act on every numba function of the process; what numba compiles and computes is
the same, only compile time and faults differ.
"""

from __future__ import annotations

import copy
import os
import threading
from pathlib import Path
from typing import NamedTuple

try:
    import fcntl
except ImportError:  # not POSIX: numba's saves stay unlocked, and rkhp compiles in one process
    fcntl = None

import numba
from numba.core import caching, inline_closurecall, sigutils

from .kernel_cache import say_once

# ----------------------------------------------------------------------------- cheaper inlining


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


def cheap_inlining(module=inline_closurecall) -> bool:
    """Replaces numba's `InlineWorker.inline_ir` and `InlineWorker.inline_function`
    (numba.core.inline_closurecall) by `_cheap_inlining`'s, once, where `inlining_precondition`
    finds them in the form it was checked on; whether they are replaced."""
    worker = module.InlineWorker
    if getattr(worker, "rkhp_cheap_inlining", False):
        return True
    if inlining_precondition(module):
        return False
    _cheap_inlining(worker)
    return True


# ----------------------------------------------------------------------------- locked saves


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


def locked_saves(module=caching) -> bool:
    """Replaces numba's `IndexDataCacheFile.save` (numba.core.caching) by `_save_locked`, once,
    where `cache_save_precondition` finds it in the form the lock was checked on; whether it is
    replaced."""
    index_file = getattr(module, "IndexDataCacheFile", None)
    if getattr(index_file, "rkhp_locked_saves", False):
        return True
    if cache_save_precondition(module):
        return False
    index_file.rkhp_original_save = index_file.save
    index_file.save = _save_locked
    index_file.rkhp_locked_saves = True
    return True


# ----------------------------------------------------------------------------- a damaged cache


def _from_interrupt(exc: BaseException) -> bool:
    """Whether ``exc`` comes from Ctrl-C: a KeyboardInterrupt in its chain of causes and contexts
    (an interrupt is never a damaged file)."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return True
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return False


#: the names numba's `Cache._load_overload` uses, in the form `heal_loads` replaces (numba 0.68):
#: the index key, the entry's data, then the compile result rebuilt from it
LOAD_OVERLOAD_NAMES = ("_enabled", "_index_key", "codegen", "_cache_file", "load", "_impl", "rebuild")
#: the names numba's `Cache.save_overload` uses (numba 0.68): `_save_overload` under a guard
SAVE_OVERLOAD_NAMES = ("_guard_against_spurious_io_errors", "_save_overload")


def heal_precondition(module=caching) -> list[str]:
    """What `heal_loads` and `warn_on_failed_saves` expect of numba's cache module and do not find
    (empty: all): `Cache._load_overload` and `Cache.save_overload` of the forms above, and
    `IndexDataCacheFile._load_index`."""
    cache = getattr(module, "Cache", None)
    index_file = getattr(module, "IndexDataCacheFile", None)
    if cache is None or index_file is None:
        return [f"{getattr(module, '__name__', module)} has no Cache or no IndexDataCacheFile"]
    missing = []
    for name, names in (("_load_overload", LOAD_OVERLOAD_NAMES), ("save_overload", SAVE_OVERLOAD_NAMES)):
        function = getattr(cache, f"rkhp_original_{name.lstrip('_')}", getattr(cache, name, None))
        if getattr(getattr(function, "__code__", None), "co_names", ()) != names:
            missing.append(f"Cache.{name} does not use exactly {names}")
    if not hasattr(index_file, "_load_index"):
        missing.append("IndexDataCacheFile has no _load_index")
    return missing


def _readable_index(load_index):
    """numba's index reader, with a damaged index read as empty (numba then compiles, and the save
    writes a new index in its place)."""

    def load(self):
        try:
            overloads = load_index(self)
        except Exception as exc:  # an index numba cannot unpickle: EOFError, UnpicklingError, ...
            if _from_interrupt(exc):
                raise
            return {}
        return overloads if isinstance(overloads, dict) else {}

    return load


def entry_holds(cache, payload, sig) -> bool:
    """Whether a cache entry's data, numba's reduced CompileResult (libdata, fndesc, environment,
    signature and five more), is of the cache's function and of the signature asked for. The
    entries of other caches (numba's code libraries) are not judged."""
    if not isinstance(getattr(cache, "_impl", None), caching.CompileResultCacheImpl):
        return True
    if not isinstance(payload, tuple) or len(payload) != 9:
        return False
    fndesc, signature = payload[1], payload[3]
    function = getattr(cache, "_py_func", None)
    if function is None or getattr(fndesc, "qualname", None) != function.__qualname__:
        return False
    try:
        args, _ = sigutils.normalize_signature(sig)
    except Exception:  # noqa: BLE001 - a signature numba cannot read: not this entry's
        return False
    return tuple(getattr(signature, "args", ())) == tuple(args)


def _checked_load_overload(self, sig, target_context):
    """numba's `Cache._load_overload`, where a damaged entry is a miss: data that cannot be read,
    that is not this function's at this signature (`entry_holds`: checked before it is rebuilt,
    so foreign machine code never reaches the JIT), or that cannot be rebuilt."""
    if not self._enabled:
        return None
    key = self._index_key(sig, target_context.codegen())
    try:
        data = self._cache_file.load(key)
        if data is None or not entry_holds(self, data, sig):
            return None
        return self._impl.rebuild(target_context, data)
    except Exception as exc:  # a truncated or garbage data file: unpickling or rebuilding fails
        if _from_interrupt(exc):
            raise
        return None


def _warning_save(save_overload):
    """numba's `Cache.save_overload`, where a save that fails with an OSError (a full disk, a
    folder that cannot be written) is a warning, once per folder: the compiled kernel is used."""

    def save(self, sig, data):
        try:
            save_overload(self, sig, data)
        except OSError as exc:
            folder = cache_root(getattr(self, "_cache_path", "") or "")
            say_once(f"save {folder}", f"cannot save compiled kernels in the cache folder {folder} "
                             f"({exc.strerror or exc}): later runs compile them again (docs/engine.md)")

    return save


def cache_root(path: str) -> str:
    """The cache folder of a function's folder (its parent: rkhp's kernels lie in
    <cache folder>/<package folder>)."""
    return str(Path(path).parent) if path else "?"


def heal_loads(module) -> None:
    """Damaged files are misses (`rkhp.taylor.kernel_cache`): numba's index reader and
    `Cache._load_overload` replaced."""
    index_file, cache = module.IndexDataCacheFile, module.Cache
    index_file.rkhp_original_load_index = index_file._load_index
    index_file._load_index = _readable_index(index_file._load_index)
    cache.rkhp_original_load_overload = cache._load_overload
    cache._load_overload = _checked_load_overload


def warn_on_failed_saves(module) -> None:
    """Failed saves are a warning (`rkhp.taylor.kernel_cache`): numba's `Cache.save_overload`
    replaced."""
    cache = module.Cache
    cache.rkhp_original_save_overload = cache.save_overload
    cache.save_overload = _warning_save(cache.save_overload)


def robust_cache(module=caching) -> bool:
    """Replaces numba's `IndexDataCacheFile._load_index`, `Cache._load_overload` (`heal_loads`)
    and `Cache.save_overload` (`warn_on_failed_saves`) of numba.core.caching, once, where
    `heal_precondition` finds them in the form they were checked on; whether they are replaced."""
    if getattr(module.Cache, "rkhp_robust", False):
        return True
    if heal_precondition(module):
        return False
    heal_loads(module)
    warn_on_failed_saves(module)
    module.Cache.rkhp_robust = True
    return True


# ----------------------------------------------------------------------------- rkhp's cache folder


#: numba's locator of a user's cache folder, which `SourcesLocator` refines (a numba without it
#: fails `locator_precondition`, and the class is then never used)
_USER_FOLDER_LOCATOR = getattr(caching, "UserProvidedCacheLocator", object)


class SourcesLocator(_USER_FOLDER_LOCATOR):
    """numba's cache locator for rkhp's compiled sources: a module's kernels are kept in
    `folder`/<its package folder> (``taylor``, ``integrators``), where numba's own locator names
    the folder by a hash of the source file's absolute path. rkhp's folder is named by the
    sources and the compiler's versions (`rkhp.taylor.compiler.cache_dir`), and numba checks a
    cached function against a hash of its file's content, so another clone, another virtual
    environment or ``pip install .`` beside ``pip install -e .`` of the same sources loads what
    any of them compiled. Functions of other files, and every function while numba has a cache
    folder of the user's (NUMBA_CACHE_DIR), are left to numba's locators (`from_function`
    answers None). The folder is not tried for writing here, as numba's locators do before they
    answer: one that cannot be written was said once (`rkhp.taylor.kernel_cache.usable_folder`),
    and numba must then keep nothing rather than write into the sources' ``__pycache__``."""

    #: rkhp's cache folder (None: none, numba's locators for every function) and the folders of
    #: rkhp's compiled sources (resolved), as `apply` sets them
    folder: str | None = None
    sources: tuple[str, ...] = ()

    def __init__(self, py_func, py_file):
        super().__init__(py_func, py_file)
        self._cache_path = os.path.join(self.folder, Path(py_file).resolve().parent.name)

    @classmethod
    def from_function(cls, py_func, py_file):
        if cls.folder is None or numba.config.CACHE_DIR or not cls.keeps(py_file):
            return None
        return cls(py_func, py_file)

    @classmethod
    def keeps(cls, py_file: str) -> bool:
        """Whether ``py_file`` is one of rkhp's compiled sources (a .py file of `sources`)."""
        path = Path(py_file).resolve()
        return path.suffix == ".py" and str(path.parent) in cls.sources


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


def sources_locator(module=caching) -> bool:
    """Puts `SourcesLocator` first in numba's `CacheImpl._locator_classes` (numba.core.caching),
    once, where `locator_precondition` finds the form it was checked on; whether it is there."""
    if locator_precondition(module):
        return False
    if SourcesLocator not in module.CacheImpl._locator_classes:
        module.CacheImpl._locator_classes.insert(0, SourcesLocator)
    return True


# ----------------------------------------------------------------------------- all of them, once


#: every patch, in the order `apply` applies them: name -> the function that applies it
PATCHES = {"cheap_inlining": cheap_inlining, "locked_saves": locked_saves, "robust_cache": robust_cache,
           "sources_locator": sources_locator}


class Applied(NamedTuple):
    """What `apply` did: the patches applied, and those left out because numba's form is not the
    one they were checked on (names of `PATCHES`)."""

    applied: tuple[str, ...]
    left_out: tuple[str, ...]


#: the first `apply`'s answer (empty until then), and the lock under which it is given (two threads
#: importing compiled modules at once apply the patches once)
_APPLIED: list[Applied] = []
_APPLYING = threading.Lock()


def apply(folder: str | None, sources: tuple[str, ...]) -> Applied:
    """Apply every patch of `PATCHES`, once: a later call changes nothing and answers as the first.
    ``folder`` is rkhp's cache folder for its compiled sources (None: numba's locators for every
    function), ``sources`` the folders of those sources (`SourcesLocator`)."""
    with _APPLYING:
        if not _APPLIED:
            SourcesLocator.folder = folder
            SourcesLocator.sources = tuple(str(Path(source).resolve()) for source in sources)
            done = {name: patch() for name, patch in PATCHES.items()}
            _APPLIED.append(Applied(tuple(name for name, ok in done.items() if ok),
                                    tuple(name for name, ok in done.items() if not ok)))
    return _APPLIED[0]


def parallel_compiles_safe() -> bool:
    """Whether processes may compile into one cache side by side (numba's saves are locked)."""
    return bool(getattr(caching.IndexDataCacheFile, "rkhp_locked_saves", False))
