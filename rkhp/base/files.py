"""Writing a file safely: never over an existing file unless asked, never through a symbolic
link, never half-written (docs/input.md "Files rkhp writes").

Every file rkhp writes (a tableau from `search --save`, a relations document, a trajectory, a
plot and its data) goes through rkhp.base.provenance.write_output, which writes by
:func:`write_atomic`: the content is written to a temporary file
in the target's folder, flushed to the disk, then moved to the name in one step (a rename), so a
full disk or an interrupt leaves the old file or nothing, never a 0-byte or truncated one.

- An existing file is replaced only with ``force`` (the command line's ``--force``); without it
  the write is refused (InputError), checked before the work (:func:`check_target`) and again at
  the rename, which does not replace a file created in between.
- A symbolic link at the name is never followed: without ``force`` it is refused, with ``force``
  the link itself is replaced by the file (its target is left as it is).
- A write that fails once the work is done (a full disk, a failing device, a folder removed
  meanwhile) is a WriteFailed (the command line's status 1), not bad input: nothing was written.
- The temporary file is named ``.NAME.XXXXXXXX.tmp`` (`TEMPORARY_GLOB`), in NAME's folder.
"""

from __future__ import annotations

import atexit
import contextlib
import os
import signal
import tempfile
from pathlib import Path

from .errors import InputError, WriteFailed
from .interrupts import INTERRUPT_SIGNALS

#: the names of the temporary files (NAME: the target's name), as docs/input.md gives them
TEMPORARY_GLOB = ".{name}.*.tmp"


def check_target(path, what: str = "output file", force: bool = False) -> Path:
    """The path, after refusing (InputError) an existing file or a symbolic link unless ``force``."""
    path = Path(path)
    if path.is_symlink():
        if not force:
            raise InputError(f"{what} {path}: is a symbolic link; rkhp does not write through links "
                             "(--force replaces the link itself, not its target)")
    elif path.exists() and not force:
        raise InputError(f"{what} {path}: the file exists; give --force to replace it")
    return path


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def atomic_path(path, what: str = "output file", force: bool = False):
    """``with atomic_path(path) as tmp:`` write the content to ``tmp`` (a new file in the same
    folder, named by `TEMPORARY_GLOB`); on leaving without an error it becomes ``path`` (see the
    module), on an error or an interrupt it is removed. OSError: WriteFailed naming the file,
    nothing written."""
    path = check_target(path, what, force)
    folder = path.parent
    tmp = None
    try:
        with _interrupts_held():  # an interrupt between the file's creation and its name kept would leave it
            try:
                fd, name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=folder)
            except OSError as exc:
                raise WriteFailed(f"{what} {path}: cannot write in {folder} ({exc.strerror or exc}); "
                                  "nothing was written") from None
            tmp = Path(name)
            _PENDING.add(tmp)
        os.fchmod(fd, 0o666 & ~_umask())
        os.close(fd)
        yield tmp
        _sync(tmp)
        if force:
            os.replace(tmp, path)  # replaces a link itself, never its target
        else:
            try:
                os.link(tmp, path)  # fails if the name was taken meanwhile: nothing replaced
            except FileExistsError:
                raise WriteFailed(f"{what} {path}: the file was created meanwhile; nothing was written "
                                  "(give --force to replace it)") from None
            tmp.unlink()
    except WriteFailed:
        raise
    except OSError as exc:
        raise WriteFailed(f"{what} {path}: cannot write the file ({exc.strerror or exc}); "
                          "nothing was written") from None
    finally:
        if tmp is not None:
            with contextlib.suppress(OSError):
                tmp.unlink()
            _PENDING.discard(tmp)


#: the temporary files being written; those an interrupt left (it can land between the generator
#: of `atomic_path` and the `with` block that would have cleaned up) are removed at the exit
_PENDING: set[Path] = set()


@atexit.register
def _remove_pending() -> None:
    for tmp in list(_PENDING):
        with contextlib.suppress(OSError):
            tmp.unlink()


@contextlib.contextmanager
def _interrupts_held():
    """The interrupt signals held back in this thread while the block runs, and delivered when it
    ends (POSIX; elsewhere nothing is held)."""
    if not hasattr(signal, "pthread_sigmask"):
        yield
        return
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, INTERRUPT_SIGNALS)  # rkhp.base.interrupts
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


def _sync(path: Path) -> None:
    """Flush a written file to the disk (a full disk shows here at the latest)."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def write_atomic(path, content: str | bytes, what: str = "output file", force: bool = False) -> None:
    """Write ``content`` (text as UTF-8) to ``path`` by :func:`atomic_path`."""
    data = content.encode("utf-8") if isinstance(content, str) else content
    with atomic_path(path, what, force) as tmp:
        with open(tmp, "wb") as fh:
            fh.write(data)
