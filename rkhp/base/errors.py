"""Errors raised by the library.

The command line turns an :class:`InputError` into one line on stderr and exit status 2, and a
:class:`NumericalFailure`, a :class:`CheckFailed`, a :class:`WriteFailed` or a
:class:`ClusterLost` into one line and exit status 1 (docs/exit-status.md). Nothing in ``rkhp``
prints: what a run should know but that does not stop it is a warning of a class defined in rkhp
(`rkhp.taylor.kernel_cache.KernelCacheWarning`), which the command line prints as one line.
"""


class RkhpError(Exception):
    """Base class of every error rkhp raises on purpose."""


class InputError(RkhpError, ValueError):
    """Bad input: a malformed tree or tableau, an unknown name, an impossible option."""


class NumericalFailure(RkhpError, ArithmeticError):
    """A computation that could not be carried out reliably (Newton diverged, step too large).
    ``trajectory``: the failed run, where one failed (`rkhp.integrate`), else None."""

    def __init__(self, *args, trajectory=None):
        super().__init__(*args)
        self.trajectory = trajectory


class CheckFailed(RkhpError):
    """A check whose answer is no: a claimed order overstated, no tableau found, axioms violated."""


class WriteFailed(RkhpError, OSError):
    """A file could not be written once the work was done (a full disk, a failing device, a
    folder gone meanwhile): nothing was written in its place."""


class ClusterLost(RkhpError):
    """The Dask scheduler of a run went away during it: its unfinished tasks cannot be had."""
