"""numba's disk cache of compiled kernels, kept working through the faults of a machine
(docs/engine.md "When the cache is damaged or cannot be written"); applied by
`rkhp.taylor.compiler`.

The cache is shared by every clone and process on a machine, and a full disk, a crash during a
save or a bad copy can leave any of its files damaged. Here:

- a damaged file is a miss, never an error: an index numba cannot read (empty, truncated,
  garbage, not a pickle of its form), a data file that cannot be read or rebuilt, or one that
  holds another function or another signature than its index entry names (two data files
  swapped). The kernel compiles once, and its save replaces the damaged file (`heal_loads`);
- a save that fails (a full disk, a folder that cannot be written) is a `KernelCacheWarning`,
  said once per process and folder; the kernel just compiled is used, the next run compiles it
  again (`warn_on_failed_saves`);
- a cache folder that cannot be used (a path through a file, a read-only folder) is said once
  and replaced by :func:`fallback_folder` (`usable_folder`).

Each patch of numba is applied only to the form of numba it was checked on (`heal_precondition`;
tests/test_dependencies.py fails loudly on another).
"""

from __future__ import annotations

import os
import stat
import tempfile
import warnings
from pathlib import Path
from typing import NamedTuple


class KernelCacheWarning(UserWarning):
    """The kernel cache cannot keep what was compiled: runs are right, but compile again (the
    command line prints it as one line, ``rkhp: warning: ...``)."""


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


def heal_precondition(module) -> list[str]:
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
    from numba.core import caching, sigutils

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


#: what was said about the cache in this process (`say_once`)
_SAID: set[str] = set()


def say_once(key: str, message: str) -> None:
    """A `KernelCacheWarning`, unless one was given with ``key`` in this process."""
    if key not in _SAID:
        _SAID.add(key)
        warnings.warn(message, KernelCacheWarning, stacklevel=2)


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
    """Damaged files are misses (see the module): numba's index reader and `Cache._load_overload`
    replaced."""
    index_file, cache = module.IndexDataCacheFile, module.Cache
    index_file.rkhp_original_load_index = index_file._load_index
    index_file._load_index = _readable_index(index_file._load_index)
    cache.rkhp_original_load_overload = cache._load_overload
    cache._load_overload = _checked_load_overload


def warn_on_failed_saves(module) -> None:
    """Failed saves are a warning (see the module): numba's `Cache.save_overload` replaced."""
    cache = module.Cache
    cache.rkhp_original_save_overload = cache.save_overload
    cache.save_overload = _warning_save(cache.save_overload)


def make_cache_robust(module) -> bool:
    """Apply `heal_loads` and `warn_on_failed_saves` to numba's cache module once, when
    `heal_precondition` finds it in the form they were checked on; whether they are applied."""
    if getattr(module.Cache, "rkhp_robust", False):
        return True
    if heal_precondition(module):
        return False
    heal_loads(module)
    warn_on_failed_saves(module)
    module.Cache.rkhp_robust = True
    return True


# ----------------------------------------------------------------------------- the folder


class Folder(NamedTuple):
    """The cache folder to use, and why the preferred one is not it (None: it is)."""

    path: Path
    reason: str | None


def fallback_folder(name: str) -> Path:
    """Where the cache goes when the preferred folder cannot be used: a folder of this user's in
    the temporary folder, ``$TMPDIR/rkhp-cache-<uid>/numba/<name>`` (``/tmp`` without TMPDIR)."""
    uid = os.getuid() if hasattr(os, "getuid") else "user"
    return Path(tempfile.gettempdir()) / f"rkhp-cache-{uid}" / "numba" / name


def unusable(path: Path) -> str | None:
    """Why ``path`` cannot be a cache folder (created where missing): a part of it that is not a
    folder, no permission, a read-only file system; None when it can."""
    try:
        os.makedirs(path, exist_ok=True)
    except OSError as exc:
        return exc.strerror or str(exc)
    if not os.access(path, os.W_OK | os.X_OK):
        return "not writable"
    return None


def _private(root: Path) -> str | None:
    """Why ``root`` (the fallback's folder in the shared temporary folder) is not this user's own:
    a link, or another user's folder (who could then place machine code for this user to run)."""
    try:
        os.makedirs(root, mode=0o700, exist_ok=True)
        info = os.lstat(root)
    except OSError as exc:
        return exc.strerror or str(exc)
    if not stat.S_ISDIR(info.st_mode):
        return "not a folder"
    if hasattr(os, "getuid") and info.st_uid != os.getuid():
        return "another user's folder"
    return None


def usable_folder(preferred: Path) -> Folder:
    """``preferred`` when it can be a cache folder, else :func:`fallback_folder` with the reason
    said once (`KernelCacheWarning`); when neither can, ``preferred`` with both reasons said (the
    runs then compile every kernel they use: saves fail, without another word)."""
    reason = unusable(preferred)
    if reason is None:
        return Folder(preferred, None)
    fallback = fallback_folder(preferred.name)
    problem = _private(fallback.parent.parent) or unusable(fallback)
    if problem is None:
        say_once(f"folder {preferred}", f"the kernel cache folder {preferred} cannot be used ({reason}): "
                           f"using {fallback} (docs/engine.md)")
        return Folder(fallback, reason)
    say_once(f"save {preferred}", f"the kernel cache folder {preferred} cannot be used ({reason}), nor {fallback} "
                        f"({problem}): compiled kernels are not kept, every run compiles them (docs/engine.md)")
    return Folder(preferred, reason)
