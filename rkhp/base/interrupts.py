"""Ctrl-C: how the library and the command line tell an interrupt from a failure.

An interrupt can land anywhere: in Python code (KeyboardInterrupt), inside a compiled kernel
(numba then reports the pending KeyboardInterrupt as a SystemError raised from it) or during a
compilation (a later call may then fail with a RuntimeError). The command line's handler of
SIGINT records the interrupt here (:func:`note`); :func:`is_interrupt` takes any exception raised
after that, or one caused by a KeyboardInterrupt, as the interrupt (docs/exit-status.md).
"""

from __future__ import annotations

_NOTED: list[bool] = []


def note() -> None:
    """Record that the user interrupted the run (called by the command line's SIGINT handler)."""
    _NOTED.append(True)


def requested() -> bool:
    """Whether an interrupt was recorded by :func:`note`."""
    return bool(_NOTED)


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
