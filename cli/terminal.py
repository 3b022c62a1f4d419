"""The terminal end of every command: Ctrl-C, stdout that cannot be written, and text from files.

- :func:`install_interrupt_handler`: Ctrl-C records the interrupt (`rkhp.base.interrupts`) and
  raises KeyboardInterrupt; a second Ctrl-C ends the process at once with status 130 and the same
  one line, whatever it is doing (waiting for workers included); once interrupted, finalisers'
  "Exception ignored" reports are not printed.
- :func:`silence_stdout`: after stdout failed (a full device, a closed pipe), point it at
  /dev/null so that the interpreter's last flush cannot print a traceback.
- :func:`plain`: text from a file or a flag, safe to print through rich (markup escaped, control
  characters written as escapes).
"""

from __future__ import annotations

import os
import signal
import sys

from rkhp.base import interrupts

INTERRUPTED = "rkhp: interrupted"
INTERRUPT_STATUS = 130


def _on_sigint(signum, frame):
    if interrupts.requested():
        try:
            os.write(2, (INTERRUPTED + "\n").encode())
        finally:
            os._exit(INTERRUPT_STATUS)
    interrupts.note()
    raise KeyboardInterrupt


def install_interrupt_handler() -> None:
    """Ctrl-C as described in the module (only in the main thread, where signals are delivered);
    after an interrupt, the errors Python can only report as "Exception ignored" (a compiler's
    object finalised half-built when the interrupt cut its compilation) are not printed."""
    try:
        signal.signal(signal.SIGINT, _on_sigint)
    except ValueError:  # not the main thread
        return
    previous = sys.unraisablehook

    def unraisable(report):
        if not interrupts.requested():
            previous(report)

    sys.unraisablehook = unraisable


def ignore_late_interrupts() -> None:
    """The command has ended (its status is chosen, its output written): Ctrl-C from here on is
    ignored. The interpreter's shutdown puts back the default action of SIGINT for a Python
    handler, so a late Ctrl-C would otherwise kill the process with no line and no status."""
    try:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    except ValueError:  # not the main thread
        pass
    _forget_unhandled_interrupt()


def _forget_unhandled_interrupt() -> None:
    """CPython records a KeyboardInterrupt that leaves code run from text (`exec` of a string:
    dataclasses and namedtuple build their methods so, during imports) as unhandled even when it
    is caught afterwards, and at exit then ends the process by SIGINT (status -2 after the one
    line). Running a constant text resets that record (Python/pythonrun.c, run_eval_code_obj)."""
    exec("None")  # noqa: S102 - a constant, not input


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
    one line on stderr, status 130."""
    import click

    click.echo(f"{INTERRUPTED}: {kept}", err=True)
    raise click.exceptions.Exit(INTERRUPT_STATUS)
