"""Errors raised by the library.

The command line turns an :class:`InputError` into one line on stderr and exit status 2, and a
:class:`NumericalFailure` or a :class:`CheckFailed` into one line and exit status 1
(docs/exit-status.md). Nothing in ``rkhp`` prints.
"""


class RkhpError(Exception):
    """Base class of every error rkhp raises on purpose."""


class InputError(RkhpError, ValueError):
    """Bad input: a malformed tree or tableau, an unknown name, an impossible option."""


class NumericalFailure(RkhpError, ArithmeticError):
    """A computation that could not be carried out reliably (Newton diverged, step too large)."""


class CheckFailed(RkhpError):
    """A check whose answer is no: a claimed order overstated, no tableau found, axioms violated."""
