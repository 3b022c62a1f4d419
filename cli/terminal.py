"""The terminal end of every command: interrupts, standard streams that are closed or cannot be
written, and text from files.

- :func:`install_interrupt_handler`: Ctrl-C (SIGINT), SIGTERM and SIGHUP record the interrupt
  (`rkhp.base.interrupts`) and raise KeyboardInterrupt; a second one ends the process at once with
  its status and one line, whatever it is doing (waiting for workers included); once
  interrupted, finalisers' "Exception ignored" reports are not printed. The line and status of
  each signal: :func:`interrupted_line`, :func:`interrupt_status`.
- :func:`open_standard_streams`: a closed stdin, stdout or stderr (`>&-`) is given a stand-in, so
  that no file rkhp opens takes its number; writing a closed stdout fails as a write does (one
  line, status 1), a closed stderr takes what is written to it.
- :func:`forgiving_stderr`: stderr that cannot be written (a full device, `2>&-`) loses what is
  written to it and changes nothing else, the exit status included.
- :func:`silence_stdout`: after stdout failed (a full device, a closed pipe), point it at
  /dev/null so that the interpreter's last flush cannot print a traceback.
- :func:`plain`: text from a file or a flag, safe to print through rich (markup escaped, control
  characters written as escapes).
"""

from __future__ import annotations

import io
import os
import signal
import sys

from rkhp.base import interrupts

INTERRUPTED = "rkhp: interrupted"
INTERRUPT_SIGNALS = interrupts.INTERRUPT_SIGNALS


def interrupted_line(signum: int | None = None) -> str:
    """The line of an interrupt by ``signum`` (default: the one recorded): ``rkhp: interrupted``
    for Ctrl-C, ``rkhp: interrupted by SIGTERM`` for another signal."""
    signum = interrupts.signal_number() if signum is None else signum
    if signum == signal.SIGINT:
        return INTERRUPTED
    return f"{INTERRUPTED} by {signal.Signals(signum).name}"


def interrupt_status(signum: int | None = None) -> int:
    """The exit status of an interrupt by ``signum`` (default: the one recorded): 128 + the
    signal's number, as a shell reports a process the signal ended (130 for Ctrl-C, 143 for
    SIGTERM, 129 for SIGHUP)."""
    return 128 + (interrupts.signal_number() if signum is None else signum)


def _on_signal(signum, frame):
    if interrupts.requested():
        try:
            os.write(2, (interrupted_line(signum) + "\n").encode())
        except OSError:
            pass
        finally:
            os._exit(interrupt_status(signum))
    interrupts.note(signum)
    raise KeyboardInterrupt


def install_interrupt_handler() -> None:
    """The signals of `INTERRUPT_SIGNALS` as described in the module (only in the main thread,
    where signals are delivered; a signal that the process was started ignoring, as under
    `nohup`, stays ignored); after an interrupt, the errors Python can only report as "Exception
    ignored" (a compiler's object finalised half-built when the interrupt cut its compilation)
    are not printed."""
    try:
        for signum in INTERRUPT_SIGNALS:
            if signal.getsignal(signum) != signal.SIG_IGN:
                signal.signal(signum, _on_signal)
    except ValueError:  # not the main thread
        return
    previous = sys.unraisablehook

    def unraisable(report):
        if not interrupts.requested():
            previous(report)

    sys.unraisablehook = unraisable


WARNING = "rkhp: warning: "


def install_warning_line() -> None:
    """rkhp's warnings (of a class defined in rkhp, such as
    `rkhp.taylor.kernel_cache.KernelCacheWarning`: a run that is right but should be known of)
    printed as one line on stderr, ``rkhp: warning: ...``; other warnings as Python prints them."""
    import warnings

    shown = warnings.showwarning
    if getattr(shown, "rkhp_line", False):
        return

    def show(message, category, filename, lineno, file=None, line=None):
        if category.__module__.split(".")[0] != "rkhp":
            return shown(message, category, filename, lineno, file, line)
        try:
            sys.stderr.write(WARNING + printable(" ".join(str(message).split())) + "\n")
        except (OSError, ValueError, AttributeError):
            pass

    show.rkhp_line = True
    warnings.showwarning = show


#: how numpy's floating-point warnings begin ("overflow encountered in multiply", "invalid value
#: encountered in subtract", ...; numpy's and scipy's own computations alike)
FLOATING_POINT_WARNING = r"(overflow|invalid value|divide by zero|underflow) encountered in "


def quiet_floating_point_warnings() -> None:
    """numpy's floating-point RuntimeWarnings (:data:`FLOATING_POINT_WARNING`) not printed: where a
    number that is not finite matters, the command says so itself (a failed run or check in one
    line, docs/exit-status.md; an error of inf in its output), and numpy's two lines for each
    operation would only bury that line. rkhp's own warnings and all others are still printed
    (:func:`install_warning_line`)."""
    import warnings

    warnings.filterwarnings("ignore", message=FLOATING_POINT_WARNING, category=RuntimeWarning)


def ignore_late_interrupts() -> None:
    """The command has ended (its status is chosen, its output written): the interrupt signals are
    ignored from here on. The interpreter's shutdown puts back the default action of a signal
    with a Python handler, so a late one would otherwise kill the process with no line and
    another status."""
    try:
        for signum in INTERRUPT_SIGNALS:
            signal.signal(signum, signal.SIG_IGN)
    except ValueError:  # not the main thread
        pass
    _forget_unhandled_interrupt()


def _forget_unhandled_interrupt() -> None:
    """CPython records a KeyboardInterrupt that leaves code run from text (`exec` of a string:
    dataclasses and namedtuple build their methods so, during imports) as unhandled even when it
    is caught afterwards, and at exit then ends the process by SIGINT (status -2 after the one
    line). Running a constant text resets that record (Python/pythonrun.c, run_eval_code_obj)."""
    exec("None")  # noqa: S102 - a constant, not input


def _is_open(fd: int) -> bool:
    try:
        os.fstat(fd)
    except OSError:
        return False
    return True


def open_standard_streams() -> None:
    """A closed standard stream given its stand-in (see the module): /dev/null at its number,
    read-only for stdin and stdout (a write to stdout then fails with EBADF, as on a closed
    one), write-only for stderr. Python leaves ``sys.stdout`` or ``sys.stderr`` None for a closed
    one; they become streams on the stand-in."""
    for fd, flags in ((0, os.O_RDONLY), (1, os.O_RDONLY), (2, os.O_WRONLY)):
        if _is_open(fd):
            continue
        opened = os.open(os.devnull, flags)
        if opened != fd:
            os.dup2(opened, fd)
            os.close(opened)
        if fd == 1 and sys.stdout is None:
            sys.stdout = io.TextIOWrapper(io.FileIO(1, "w", closefd=False), encoding="utf-8", errors="backslashreplace")
        if fd == 2 and sys.stderr is None:
            sys.stderr = io.TextIOWrapper(io.FileIO(2, "w", closefd=False), encoding="utf-8",
                                          errors="backslashreplace", line_buffering=True)


class _ForgivingStderr(io.RawIOBase):
    """File descriptor 2, whose write errors lose the text: after the first, fd 2 points at
    /dev/null (the interpreter's last flush then cannot fail either)."""

    def __init__(self, fd: int = 2):
        super().__init__()
        self._fd = fd

    def writable(self) -> bool:
        return True

    def fileno(self) -> int:
        return self._fd

    def isatty(self) -> bool:
        try:
            return os.isatty(self._fd)
        except OSError:
            return False

    def write(self, data) -> int:
        view = memoryview(data)
        try:
            while view:
                view = view[os.write(self._fd, view):]
        except OSError:
            _point_at_devnull(self._fd)
        return len(data)


def _point_at_devnull(fd: int) -> None:
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, fd)
        os.close(devnull)
    except OSError:
        pass


def forgiving_stderr() -> None:
    """``sys.stderr`` on `_ForgivingStderr` (see the module), with the encoding and error handler
    of Python's own stderr, line-buffered."""
    current = sys.stderr
    encoding = getattr(current, "encoding", None) or "utf-8"
    sys.stderr = io.TextIOWrapper(io.BufferedWriter(_ForgivingStderr()), encoding=encoding,
                                  errors="backslashreplace", line_buffering=True)


def silence_stdout() -> None:
    """Point file descriptor 1 at /dev/null and drop what Python still buffers for it."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    except (OSError, ValueError, AttributeError):
        pass


_CONTROL = {i: f"\\x{i:02x}" for i in (*range(0x20), 0x7F)}
_CONTROL.update({ord("\n"): "\\n", ord("\t"): "\\t", ord("\r"): "\\r"})
_CONTROL.update({i: f"\\u{i:04x}" for i in (*range(0x80, 0xA0), 0x2028, 0x2029, 0x202E, 0x200E, 0x200F)})


def printable(text) -> str:
    """``text`` with control characters (newline included) written as Python escapes: one line,
    nothing that moves the cursor or fakes another line."""
    return str(text).translate(_CONTROL)


def plain(text) -> str:
    """``text`` from a file or a flag, for a rich console: control characters escaped
    (:func:`printable`) and rich markup escaped, so that brackets print as they are."""
    from rich.markup import escape

    return escape(printable(text))


def stop_interrupted(kept: str = "the rows finished so far are shown") -> None:
    """End a command whose run an interrupt cut short, after its partial result was printed: the
    one line on stderr, the interrupt's status (:func:`interrupt_status`)."""
    import click

    click.echo(f"{interrupted_line()}: {kept}", err=True)
    raise click.exceptions.Exit(interrupt_status())
