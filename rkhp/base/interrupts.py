"""Ctrl-C: how the library and the command line tell an interrupt from a failure.

An interrupt is Ctrl-C (SIGINT), or a request to end that the command line handles the same way:
SIGTERM (a batch scheduler's time limit, `timeout`, `docker stop`) and SIGHUP (a closed terminal
or ssh session). It can land anywhere: in Python code (KeyboardInterrupt), inside a compiled kernel
(numba then reports the pending KeyboardInterrupt as a SystemError raised from it) or during a
compilation (a later call may then fail with a RuntimeError). The command line's handler of
SIGINT records the interrupt here (:func:`note`); :func:`is_interrupt` takes any exception raised
after that, or one caused by a KeyboardInterrupt, as the interrupt (docs/exit-status.md).
"""

from __future__ import annotations

import signal

#: the signals handled as an interrupt: Ctrl-C, a request to end (batch schedulers' time limits,
#: `timeout`, `docker stop`), a closed terminal or ssh session
INTERRUPT_SIGNALS = tuple(getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, name))

_NOTED: list[int] = []


def note(signum: int = signal.SIGINT) -> None:
    """Record that the run was interrupted by signal ``signum`` (called by the command line's
    handler of SIGINT, SIGTERM and SIGHUP)."""
    _NOTED.append(int(signum))


def requested() -> bool:
    """Whether an interrupt was recorded by :func:`note`."""
    return bool(_NOTED)


def signal_number() -> int:
    """The signal of the first interrupt recorded (SIGINT when none was)."""
    return _NOTED[0] if _NOTED else int(signal.SIGINT)


def is_interrupt(exc: BaseException) -> bool:
    """Whether ``exc`` is, or comes from, an interrupt: a KeyboardInterrupt in its chain of causes
    and contexts, or any exception once :func:`note` has recorded one."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return True
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return requested()


class Interrupted(KeyboardInterrupt):
    """An interrupt raised from inside a task, carrying the part of its result finished before it
    (``partial``), which an in-process run keeps (`rkhp.base.executors.run_until_interrupted`)."""

    def __init__(self, partial):
        super().__init__()
        self.partial = partial
