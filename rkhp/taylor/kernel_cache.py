"""numba's disk cache of compiled kernels, kept working through the faults of a machine
(docs/engine.md "When the cache is damaged or cannot be written"): the cache folder and what is
said about the cache here, numba's loads and saves replaced by `rkhp.taylor.numba_patches`.

The cache is shared by every clone and process on a machine, and a full disk, a crash during a
save or a bad copy can leave any of its files damaged. Here:

- a damaged file is a miss, never an error: an index numba cannot read (empty, truncated,
  garbage, not a pickle of its form), a data file that cannot be read or rebuilt, or one that
  holds another function or another signature than its index entry names (two data files
  swapped). The kernel compiles once, and its save replaces the damaged file (`rkhp.taylor.numba_patches.heal_loads`);
- a save that fails (a full disk, a folder that cannot be written) is a `KernelCacheWarning`,
  said once per process and folder; the kernel just compiled is used, the next run compiles it
  again (`rkhp.taylor.numba_patches.warn_on_failed_saves`);
- a cache folder that cannot be used (a path through a file, a read-only folder) is said once
  and replaced by :func:`fallback_folder` (`usable_folder`).

Each patch of numba is applied only to the form of numba it was checked on
(`rkhp.taylor.numba_patches.heal_precondition`; tests/test_dependencies.py fails loudly on
another).
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


#: what was said about the cache in this process (`say_once`)
_SAID: set[str] = set()


def say_once(key: str, message: str) -> None:
    """A `KernelCacheWarning`, unless one was given with ``key`` in this process."""
    if key not in _SAID:
        _SAID.add(key)
        warnings.warn(message, KernelCacheWarning, stacklevel=2)


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
